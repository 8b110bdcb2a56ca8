"""``abacus run``: the main job — simulate, image, detect, locate, count; dataset and figures.

The run folder appears complete or not at all: the numbers (dataset, detections, counts, the
resolved scene, the beam table) are written into a hidden staging folder next to it, which is
renamed into place when they are all there. Figure folders appear after the numbers are saved,
each again staged and renamed, so a failure or Ctrl-C while drawing never costs the numbers and
never leaves half a folder. The figures are drawn through :mod:`abacus.figures.drawing`
(in this process, or by a standard-library process pool where a core is spare) from the run's
own data: the first ping's images once the pings are simulated, the detection and count
figures once they are counted, each into a hidden scratch folder that is moved into the run
folder when the numbers are saved.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import warnings
from pathlib import Path

from abacus.cli.common import (Progress, add_output_options, check_output, check_scene_resources,
                                  load, ping_list, prefetch)

_T0 = __import__("time").perf_counter()   # the command's own clock starts at its import

HELP = "the main job: simulate, image, detect, locate, count"


def add_parser(sub):
    r = sub.add_parser("run", help=HELP)
    r.add_argument("scene", help="scene file (YAML) or a built-in scene's name (e.g. default)")
    r.add_argument("-o", "--output", help="output folder (default runs/<scene name>)")
    r.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    r.add_argument("--plots", action=argparse.BooleanOptionalAction, default=True,
                   help="draw the figures (default; --no-plots: numbers only)")
    r.add_argument("--images", choices=["none", "native", "full"], default="none",
                   help="store the images in run.nc: none (default; they follow from the samples), "
                        "native (at the data's range sampling) or full (every interpolated row)")
    add_output_options(r)
    r.set_defaults(func=command)


def default_run_folder(name: str) -> Path:
    """``runs/<name>``, the name reduced to letters, digits, '-', '_' and '.' (no separators,
    no '..'), so a scene's name can never point outside ``runs/``."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "scene"
    return Path("runs") / safe


def command(args) -> int:
    import time
    from contextlib import ExitStack

    with ExitStack() as stack:
        # the figures' drawing starts first: a pool's workers import matplotlib while this
        # process imports and simulates (abacus.figures.drawing)
        drawing = None
        if args.plots:
            drawing = stack.enter_context(figure_drawing(getattr(args, "standalone", False)))
        import processing
        from abacus.cli.beams import beam_numbers
        from acoustics.simulation.run import simulate
        from acoustics.simulation.stages import StageLog
        from processing.base.atomic import staged, write_text_atomic
        from processing.base.dataset import write_tree
        log = StageLog()
        log.add("start", time.perf_counter() - _T0)
        with log.stage("load"):
            scene = load(args.scene)
        if args.output:
            outdir = check_output(args.output, overwrite=args.overwrite, folder=True)
        else:   # runs/<name>: the one folder abacus creates for you
            outdir = default_run_folder(scene.name)
            outdir.parent.mkdir(exist_ok=True)
            outdir = check_output(outdir, overwrite=args.overwrite, folder=True)
        pings = ping_list(scene, args.pings)
        check_scene_resources(scene, args, pings=len(pings) if pings else None, images=args.images,
                              output=outdir / "run.nc", figures=args.plots)
        figures = stack.enter_context(_RunFigures(drawing, outdir)) if drawing is not None else None
        if figures is not None:
            figures.beams(scene)
        print(f"scene '{scene.name}' ({args.scene}): {scene.pings.count} ping(s), "
              f"sha256 {scene.sha256()[:12]}")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with log.stage("simulate"):
                # scoring's assignment solver: 0.2 s of imports the processing would wait for
                prefetch("scipy.optimize")
                tree = simulate(scene, pings=pings, progress=Progress("simulate"))
            with log.stage("process"):
                if figures is not None:
                    figures.images(tree)      # the first ping's, drawn while the run processes
                tree = processing.count(tree, images=args.images)
                result = processing.count_summary(tree)
                if figures is not None:
                    figures.counts(tree)      # drawn while the numbers are written
        notes = run_notes(tree, caught)
        result["summary"]["warnings"] = notes
        with log.stage("write"), staged(outdir) as tmp:
            tmp.mkdir()
            write_tree(tree, tmp / "run.nc")
            processing.write_csv(tree, tmp / "detections.csv")
            write_text_atomic(tmp / "counts.json", json.dumps(result, indent=1))
            write_text_atomic(tmp / "scene.resolved.yaml", scene.resolved_text())
            write_text_atomic(tmp / "beams.json", json.dumps(beam_numbers(scene), indent=1))
        print()
        print(processing.format_counts(result))
        made = "run.nc (dataset), detections.csv, counts.json, beams.json, scene.resolved.yaml"
        if figures is not None:
            with log.stage("figures"):
                figures.place(scene)
            made += ", images/, counts/, beams/"
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    print(f"\noutputs in {outdir}/: {made}")
    print(f"time: {log.summary()} (start: interpreter and imports)")
    return 0


def figure_drawing(standalone: bool):
    """How ``abacus run`` draws its figures: in a pool of one worker process where the process
    is the command's own (``standalone``: not a program that called ``main(argv)``, whose
    script a "spawn" worker would run again) and has a second core for it (measured in
    docs/performance.md, "End to end"); else in this process."""
    from abacus.figures.drawing import Drawing, PoolDrawing
    from processing.base.resources import usable_cores
    return PoolDrawing(workers=1) if standalone and usable_cores() >= 2 else Drawing()


def run_notes(tree, caught) -> list[str]:
    """What deserves a look in a run, once each: warnings raised while simulating and
    processing (non-Rayleigh noise, a dataset without subarray B, ...) and ADC clipping."""
    from processing.base.dataset import ELEMENT_GROUP
    notes = []
    for w in caught:
        text = str(w.message)
        if text not in notes:
            notes.append(text)
    clipped = tree[ELEMENT_GROUP].ds.get("adc_clipped_samples")
    if clipped is not None and int(clipped.sum()):
        n = int(clipped.sum())
        pings = int((clipped.sum("beam") > 0).sum())
        notes.append(f"the ADC clipped {n} samples in {pings} ping(s): echoes beyond its range "
                     f"are distorted (sampling.adc.bits, sampling.adc.scale_counts)")
    return notes


class _RunFigures:
    """The run's figures, drawn (by :mod:`abacus.figures.drawing`) into scratch folders next
    to the run folder, which does not exist until the numbers are saved; :meth:`place` moves
    each folder into the run folder, staged, once they are saved. Leaving the ``with`` block
    stops the drawing before it removes what is left of the scratch folders."""

    def __init__(self, drawing, outdir: Path):
        from contextlib import ExitStack
        self._drawing, self._outdir = drawing, outdir
        self._scratch = ExitStack()
        self._folders: dict = {}
        self._beam_pngs = None       # the beam figures' PNGs, when the geometry cache has them

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        try:
            self._drawing.close(cancel=kind is not None)    # nothing writes into the folders
        finally:
            self._scratch.close()
        return False

    def _submit(self, name: str, job, *data):
        """Draw ``job(data, folder)`` for each ``data``, into the scratch folder ``name``."""
        from processing.base.atomic import scratch
        if name not in self._folders:
            # named so that any later write of the run folder removes it if this process is killed
            folder = self._scratch.enter_context(scratch(self._outdir.parent, f"{self._outdir.name}.{name}"))
            self._folders[name] = (folder, [])
        folder, futures = self._folders[name]
        futures.extend(self._drawing.submit(job, d, folder) for d in data)

    def images(self, tree):
        """images/: the image figures of the dataset's first ping."""
        from abacus.figures.plots import draw_image_figures, image_figure_data
        from processing.records import figure_images
        self._submit("images", draw_image_figures, image_figure_data(figure_images(tree, [0])))

    def counts(self, tree):
        """counts/: detections of the first three pings, and counts per ping."""
        from abacus.figures.plots import count_figure_data, draw_counts_figure, draw_detection_figures
        n = tree["Processing/Counts"].sizes["ping_time"]
        data = count_figure_data(tree, pings=range(min(n, 3)))
        # the pings drawn by one job share one figure (made once, its data changed per ping)
        self._submit("counts", draw_detection_figures, data["detections"])
        self._submit("counts", draw_counts_figure, data["counts"])

    def beams(self, scene):
        """beams/: copied from the geometry cache, or drawn (and then cached)."""
        from abacus.cli.beams import beam_cuts_of, cached_beam_figures
        from abacus.figures.beams import plot_beam_figures
        self._beam_pngs = cached_beam_figures(scene)
        if self._beam_pngs is None:
            self._submit("beams", plot_beam_figures, beam_cuts_of(scene))

    def place(self, scene):
        """Wait for every drawing; each figure folder appears whole in the run folder."""
        import os

        from abacus.cli.beams import store_beam_figures, write_beam_figures
        from processing.base.atomic import staged
        if self._beam_pngs is not None:
            with staged(self._outdir / "beams") as tmp:
                write_beam_figures(self._beam_pngs, tmp)
        for name, (folder, futures) in self._folders.items():
            self._drawing.wait(futures)
            if name == "beams":
                store_beam_figures(scene, folder)     # the next run copies them
            with staged(self._outdir / name) as tmp:
                os.replace(folder, tmp)
