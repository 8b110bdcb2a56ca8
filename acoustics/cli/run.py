"""``abacus run``: the main job — simulate, image, detect, locate, count; dataset and figures.

The run folder appears complete or not at all: the numbers (dataset, detections, counts, the
resolved scene, the beam table) are written into a hidden staging folder next to it, which is
renamed into place when they are all there. Figure folders appear after the numbers are saved,
each again staged and renamed, so a failure or Ctrl-C while drawing never costs the numbers and
never leaves half a folder. The figures are drawn by a helper process
(:mod:`acoustics.cli.figure_worker`) beside this one: it starts importing matplotlib at once,
draws the first ping's images (into a hidden scratch folder) while the pings are processed, and
shares the remaining figures with this process once the numbers are saved.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import warnings
from pathlib import Path

from acoustics.cli.common import (Progress, add_output_options, check_output, check_scene_resources,
                                  load, ping_list)

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

    import processing
    from acoustics.cli.beams import beam_numbers
    from acoustics.simulation.run import simulate
    from acoustics.simulation.stages import StageLog
    from processing.atomic import staged, write_text_atomic
    from processing.dataset import write_tree
    log = StageLog()
    log.add("start", time.perf_counter() - _T0)
    with ExitStack() as stack:
        # the figure helper starts first: it imports matplotlib while this process computes
        figures = None
        if args.plots:
            from acoustics.cli.figure_worker import FigureWorker
            figures = stack.enter_context(FigureWorker())
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
        print(f"scene '{scene.name}' ({args.scene}): {scene.pings.count} ping(s), "
              f"sha256 {scene.sha256()[:12]}")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with log.stage("simulate"):
                tree = simulate(scene, pings=pings, progress=Progress("simulate"))
            early = None
            if figures is not None:
                # the first ping's images depend on nothing later: drawn while the rest is processed
                early = _draw_image_figures_early(stack, figures, tree, outdir)
            with log.stage("process"):
                tree = processing.count(tree, images=args.images)
                result = processing.count_summary(tree)
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
                _figures(scene, tree, outdir, figures, early)
            made += ", images/, counts/, beams/"
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    print(f"\noutputs in {outdir}/: {made}")
    print(f"time: {log.summary()} (start: interpreter and imports)")
    return 0


def run_notes(tree, caught) -> list[str]:
    """What deserves a look in a run, once each: warnings raised while simulating and
    processing (non-Rayleigh noise, a dataset without subarray B, ...) and ADC clipping."""
    from processing.dataset import ELEMENT_GROUP
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


def _draw_image_figures_early(stack, figures, tree, outdir: Path):
    """Send the first ping's image figures to the helper, to be drawn into a scratch folder
    next to the run folder (which does not exist until the numbers are saved); returns
    (folder, ticket)."""
    from processing.atomic import scratch
    from processing.plots import image_figure_data
    from processing.products import figure_images
    # named so that any later write of the run folder removes it if this process is killed
    folder = stack.enter_context(scratch(outdir.parent, f"{outdir.name}.images"))
    data = image_figure_data(figure_images(tree, [0]), ping=0)
    return folder, figures.submit("draw_image_figures", data, folder)


def _figures(scene, tree, outdir: Path, figures, early):
    """The run's figures, after its numbers are saved (each folder staged): the helper draws the
    images (begun while processing) and the first detection figures; this process draws the
    rest — the two share the machine's cores."""
    import os

    from acoustics.cli.beams import beam_figures
    from processing.atomic import staged
    from processing.plots import count_figure_data, draw_counts_figure, draw_detection_figure
    n = tree["Processing/Counts"].sizes["ping_time"]
    data = count_figure_data(tree, pings=range(min(n, 3)))
    mine = data["detections"][-1:] if len(data["detections"]) > 1 else []
    with staged(outdir / "counts") as tmp_counts:
        tickets = [figures.submit("draw_detection_figure", d, tmp_counts)
                   for d in data["detections"][:len(data["detections"]) - len(mine)]]
        for d in mine:
            draw_detection_figure(d, tmp_counts)
        draw_counts_figure(data["counts"], tmp_counts)
        with staged(outdir / "beams") as tmp:
            beam_figures(scene, tmp)
        folder, ticket = early
        figures.result(ticket)
        with staged(outdir / "images") as tmp:
            os.replace(folder, tmp)
        for t in tickets:
            figures.result(t)
