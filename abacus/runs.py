"""The main job of abacus — simulate, image, detect, locate, count — into a run folder.

:func:`run` is what ``abacus run`` does, as a function (``abacus.run(...)``): the run folder
appears complete or not at all. The numbers (dataset, detections, counts, the resolved scene,
the beam table) are written into a hidden staging folder next to it, which is renamed into place
when they are all there. Figure folders appear after the numbers are saved, each again staged
and renamed, so a failure or an interrupt while drawing never costs the numbers and never leaves
half a folder. The figures are drawn through :mod:`abacus.figures.drawing` (in this process, or
by a standard-library process pool) from the run's own data: the first ping's images once the
pings are simulated, the detection and count figures once they are counted, each into a hidden
scratch folder that is moved into the run folder when the numbers are saved.
"""
from __future__ import annotations

import json
import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

#: the run as SONAR-netCDF4 2.0 (``abacus run --format sonar-netcdf4-2``)
SONAR_NETCDF2_FILE = "run.sonar-netcdf4-2.nc"

__all__ = ["run", "RunResult", "default_run_folder", "run_notes"]


@dataclass
class RunResult:
    """What a run made.

    Attributes
    ----------
    folder : Path
        The run folder: run.nc, detections.csv, counts.json, beams.json, scene.resolved.yaml
        and, with figures, images/, counts/, beams/.
    summary : dict
        The counts per ping and their summary (what counts.json holds,
        :func:`processing.count_summary`), with the run's warnings under ``summary.warnings``.
    tree : xarray.DataTree
        The dataset as written to run.nc (samples, /Processing/Detections and Counts).
    notes : list of str
        Warnings worth a look (non-Rayleigh noise, ADC clipping, ...), once each.
    made : list of str
        The outputs in the folder.
    stages : StageLog
        The run's stages and their wall times.
    """

    folder: Path
    summary: dict
    tree: object
    notes: list = field(default_factory=list)
    made: list = field(default_factory=list)
    stages: object = None


def run(scene, output=None, *, pings: int | None = None, plots: bool = True, images: str = "none",
        overwrite: bool = False, max_memory_gb: float | None = None, drawing=None, progress=None,
        announce=None, started_s: float | None = None, sonar_netcdf2: bool = False) -> RunResult:
    """Simulate, image, detect, locate and count a scene into a run folder, with its figures.

    Parameters
    ----------
    scene : Scene, str or Path
        A run file (a scene file with its ``processing:`` block), a built-in scene's name
        (``"default"``), or a :class:`~acoustics.scene.Scene`.
    output : str or Path, optional
        The run folder (a new one; its parent must exist). Default ``runs/<scene name>``.
    pings : int, optional
        Number of pings (the scene's first ``pings``); default the scene's.
    plots : bool
        Draw the figures.
    images : {"none", "native", "full"}
        Store the images in run.nc (they follow from the samples and the settings otherwise).
    overwrite : bool
        Replace an existing run folder.
    max_memory_gb : float, optional
        Memory the run may use (default: ``$ABACUS_MAX_MEMORY_GB``, else half the machine's);
        a larger run is refused before it starts.
    drawing : abacus.figures.drawing.Drawing, optional
        How the figures are drawn (default: in this process).
    progress : callable(done, total), optional
        Called after each simulated ping.
    announce : callable(str), optional
        Told what the run is about to do (the command line prints it).
    started_s : float, optional
        ``time.perf_counter()`` when the caller started (the stage log's "start").
    sonar_netcdf2 : bool
        Also write ``run.sonar-netcdf4-2.nc``: the run as SONAR-netCDF4 2.0, with its single
        targets and gridded Sv (run.nc stays 1.0).

    Returns
    -------
    RunResult

    Raises
    ------
    acoustics.scene.SceneError, processing.base.resources.ResourceError,
    abacus.cli.common.UsageError (an output that exists without ``overwrite``)
    """
    from contextlib import ExitStack

    import processing
    from abacus.cli.beams import beam_numbers
    from abacus.cli.common import check_output, check_scene_resources, ping_list, prefetch
    from abacus.runfile import load_run, resolve_processing
    from acoustics.simulation.run import simulate
    from acoustics.simulation.stages import StageLog
    from processing.base.atomic import staged, write_text_atomic
    from processing.base.dataset import write_tree
    log = StageLog()
    if started_s is not None:
        log.add("start", time.perf_counter() - started_s)
    with log.stage("load"):
        scene = load_run(scene) if isinstance(scene, (str, Path)) else resolve_processing(scene)
    if output is not None:
        outdir = check_output(output, overwrite=overwrite, folder=True)
    else:   # runs/<name>: the one folder abacus creates for you
        outdir = default_run_folder(scene.name)
        outdir.parent.mkdir(exist_ok=True)
        outdir = check_output(outdir, overwrite=overwrite, folder=True)
    chosen = ping_list(scene, pings)
    from types import SimpleNamespace
    check_scene_resources(scene, SimpleNamespace(max_memory=max_memory_gb), pings=len(chosen) if chosen else None, images=images,
                          output=outdir / "run.nc", figures=plots)
    made = ["run.nc", "detections.csv", "counts.json", "beams.json", "scene.resolved.yaml"]
    if sonar_netcdf2:
        made.insert(1, SONAR_NETCDF2_FILE)
    with ExitStack() as stack:
        figures = None
        if plots:
            if drawing is None:
                from abacus.figures.drawing import Drawing
                drawing = stack.enter_context(Drawing())
            figures = stack.enter_context(_RunFigures(drawing, outdir))
            figures.beams(scene)
        if announce is not None:
            where = f" ({scene.source_path.name})" if scene.source_path is not None else ""
            announce(f"scene '{scene.name}'{where}: {len(chosen) if chosen else scene.pings.count} "
                     f"ping(s), sha256 {scene.sha256()[:12]}")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with log.stage("simulate"):
                # scoring's assignment solver: 0.2 s of imports the processing would wait for
                prefetch("scipy.optimize")
                tree = simulate(scene, pings=chosen, progress=progress)
            with log.stage("process"):
                if figures is not None:
                    figures.images(tree)      # the first ping's, drawn while the run processes
                tree = processing.count(tree, images=images)
                result = processing.count_summary(tree)
                if figures is not None:
                    figures.counts(tree)      # drawn while the numbers are written
        notes = run_notes(tree, caught)
        result["summary"]["warnings"] = notes
        with log.stage("write"), staged(outdir) as tmp:
            tmp.mkdir()
            write_tree(tree, tmp / "run.nc")
            if sonar_netcdf2:
                processing.write_sonar_netcdf2(tree, tmp / SONAR_NETCDF2_FILE, single_targets=True,
                                               gridded=True)
            processing.write_csv(tree, tmp / "detections.csv")
            write_text_atomic(tmp / "counts.json", json.dumps(result, indent=1))
            write_text_atomic(tmp / "scene.resolved.yaml", scene.resolved_text())
            write_text_atomic(tmp / "beams.json", json.dumps(beam_numbers(scene), indent=1))
        if figures is not None:
            with log.stage("figures"):
                figures.place(scene)
            made += ["images/", "counts/", "beams/"]
    return RunResult(outdir, result, tree, notes, made, log)


def default_run_folder(name: str) -> Path:
    """``runs/<name>``, the name reduced to letters, digits, '-', '_' and '.' (no separators,
    no '..'), so a scene's name can never point outside ``runs/``."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "scene"
    return Path("runs") / safe


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
        from abacus.figures.calibrated import echogram_calibration
        from abacus.figures.plots import draw_image_figures, image_figure_data
        from processing.records import figure_images
        im = figure_images(tree, [0])
        self._submit("images", draw_image_figures,
                     image_figure_data(im, calibration=echogram_calibration(tree, im)))

    def counts(self, tree):
        """counts/: detections of the first three pings, and counts per ping."""
        from abacus.figures.plots import count_figure_data, draw_counts_figure, draw_detection_figures
        from processing.base.contract import COUNTS_GROUP
        from processing.base.dataset import group_of
        n = group_of(tree, COUNTS_GROUP).sizes["ping_time"]
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
