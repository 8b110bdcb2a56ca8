"""Monte Carlo experiments (thesis chapter 6): many pings, optionally a sweep of one parameter,
every ping simulated, imaged, detected, located, counted, scored and echo-integrated — in
parallel with Dask, resumable, and summarised in a dataset and a report.

Tasks are independent: a task is one ping of one scene (for a sweep of a processing setting, one
ping evaluated under every sweep point; for a sweep of a scene parameter, one ping of one scene
variant). Each draws its randomness from (scene seed, ping index) only, so the results do not
depend on the number of workers or on the order tasks finish. A finished task is written at once
to ``DIR/parts/`` (atomically); a rerun of the same experiment skips what is there, so an
interrupted experiment resumes where it stopped.

Sweeps are ``KEY=START:STOP:STEP`` (inclusive of STOP when it falls on the grid) or
``KEY=V1,V2,...``. KEY is a dotted path into the scene file (``noise.sigma_counts``,
``processing.detect.pfa_image``, ``targets.populations[0].count``) or ``threshold``: a fixed
threshold ``processing.detect.value`` in the scene's ``value_units`` (so a scene with
``value_units: thesis`` sweeps the thesis' 600–2000 of §6.3.6).
"""
from __future__ import annotations

import hashlib
import json
import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from processing.base.atomic import write_bytes_atomic, write_text_atomic
from processing.base.dataset import write_dataset
from processing.base.resources import usable_cores
from abacus.results import assemble_results, load_part, save_part
from abacus.runfile import resolve_processing, settings_of

__all__ = ["Sweep", "parse_sweep", "ExperimentError", "run_experiment", "experiment_plan"]

#: keys a sweep may name besides dotted scene paths: (path, other settings it implies)
SWEEP_ALIASES = {"threshold": ("processing.detect.value", {"processing.detect.method": "fixed"})}
PARTS = "parts"
RESULTS_VERSION = 1


class ExperimentError(ValueError):
    """A bad sweep, a bad option, or an output folder that holds another experiment."""


@dataclass(frozen=True)
class Sweep:
    """One parameter and its values."""

    key: str
    values: tuple
    text: str

    @property
    def path(self) -> str:
        return SWEEP_ALIASES.get(self.key, (self.key, {}))[0]

    @property
    def implies(self) -> dict:
        return SWEEP_ALIASES.get(self.key, (self.key, {}))[1]

    @property
    def processing_only(self) -> bool:
        """Whether only processing changes (the pings are simulated once for all values)."""
        return self.path.startswith("processing.")

    def label(self, value) -> str:
        return f"{self.key}={value:g}" if isinstance(value, float) else f"{self.key}={value}"


def parse_sweep(text: str) -> Sweep:
    """``KEY=START:STOP:STEP`` or ``KEY=V1,V2,...`` → :class:`Sweep`.

    Raises
    ------
    ExperimentError
        With the accepted forms.
    """
    form = "give KEY=START:STOP:STEP (e.g. threshold=600:2000:50) or KEY=V1,V2,... "
    if "=" not in text:
        raise ExperimentError(f"--sweep {text!r}: {form}")
    key, spec = (s.strip() for s in text.split("=", 1))
    if not key or not spec:
        raise ExperimentError(f"--sweep {text!r}: {form}")
    try:
        if ":" in spec:
            parts = [float(x) for x in spec.split(":")]
            if len(parts) != 3:
                raise ValueError
            start, stop, step = parts
            if not step > 0 or stop < start:
                raise ExperimentError(f"--sweep {text!r}: STEP must be > 0 and STOP >= START")
            n = int(math.floor((stop - start) / step + 1e-9)) + 1
            if n > 10_000:
                raise ExperimentError(f"--sweep {text!r}: {n} points; at most 10000")
            values = tuple(round(start + i * step, 12) for i in range(n))
        else:
            values = tuple(_number(v.strip()) for v in spec.split(","))
    except ExperimentError:
        raise
    except ValueError:
        raise ExperimentError(f"--sweep {text!r}: {form}(numbers only)") from None
    return Sweep(key, values, text)


def _number(v: str):
    f = float(v)
    return int(f) if f.is_integer() and "." not in v and "e" not in v.lower() else f


# ------------------------------------------------------------------- the plan
def _variant(scene, updates: dict, what: str):
    """The scene with ``updates`` ({dotted path: value}) applied, validated again."""
    from acoustics.scene import SceneError
    try:
        return scene.with_updates(updates, what=what)
    except SceneError as exc:
        raise ExperimentError(str(exc)) from None


@dataclass
class Point:
    """One setting of the experiment: its label, sweep value, scene and processing settings."""

    label: str
    value: float
    scene: object
    settings: object


def experiment_plan(scene, sweep: Sweep | None):
    """The settings of an experiment: the scene as written, then one per sweep value."""
    # every processing key present, so a sweep may set any of them
    scene = resolve_processing(scene)
    points = [Point("scene", float("nan"), scene, settings_of(scene))]
    if sweep is None:
        return points
    for v in sweep.values:
        updates = {**sweep.implies, sweep.path: v}
        var = _variant(scene, updates, f"--sweep {sweep.text}")
        points.append(Point(sweep.label(v), float(v), var, settings_of(var)))
    return points


def _tasks(points, pings, sweep, track_pings: int | None = None):
    """(task id, scene point index, pings, setting indices): one per simulated ping, or with
    ``track_pings`` one per run of that many consecutive pings (the last run may be shorter),
    which the task simulates together and tracks."""
    n = int(track_pings) if track_pings else 1
    runs = [list(pings[i:i + n]) for i in range(0, len(pings), n)]
    kind = "run" if track_pings else "ping"
    if sweep is None or sweep.processing_only:
        return [(f"{kind}{r[0]:06d}", 0, r, list(range(len(points)))) for r in runs]
    return [(f"point{j:03d}_{kind}{r[0]:06d}", j, r, [j]) for j in range(len(points)) for r in runs]


# ------------------------------------------------------------------ one task
_WORKER_CACHE: dict = {}


def _scene_in_worker(text: str, source: str | None):
    from acoustics.scene import scene_from_resolved_text
    key = hashlib.sha256((text + str(source)).encode()).hexdigest()
    if key not in _WORKER_CACHE:
        sc = scene_from_resolved_text(text, source_path=source)
        _WORKER_CACHE.clear()
        _WORKER_CACHE[key] = sc
    return _WORKER_CACHE[key]


def run_task(payload: dict) -> dict:
    """Simulate the task's pings and evaluate them under the task's settings (runs on a worker);
    with ``payload["track"]``, also track them under each setting and score the tracks against
    the truth (:data:`abacus.results.TRACK_KEYS`).

    Returns plain numpy arrays and bytes only, so that any Dask worker can send it back.
    """
    import warnings

    import numba

    from abacus.evaluate import evaluate
    from processing.settings import ProcessingSettings

    from acoustics.scene import SceneWarning
    from acoustics.simulation.run import simulate
    t0 = time.perf_counter()
    numba.set_num_threads(max(1, min(payload.get("threads", 1), numba.config.NUMBA_NUM_THREADS)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = _scene_in_worker(payload["scene_text"], payload["source"])
    settings = [ProcessingSettings.model_validate_json(s) for s in payload["settings"]]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tree = simulate(scene, pings=list(payload["pings"]))
        ev = evaluate(tree, settings)
        tracking = _track_scores(tree, settings) if payload.get("track") else None
        figure = _figure_bytes(tree, settings[0], payload["pings"][0]) if payload.get("figure") else b""
    from processing.base.dataset import ELEMENT_GROUP
    clipped = tree[ELEMENT_GROUP].ds.get("adc_clipped_samples")
    extra = (["the ADC clipped samples (sampling.adc.bits, sampling.adc.scale_counts)"]
             if clipped is not None and int(clipped.sum()) else [])
    # one line per kind of warning (the numbers in a message differ from ping to ping)
    notes = sorted({n.split("(")[0].strip()[:200] for n in list(ev["notes"]) + extra
                    + [str(w.message) for w in caught if not issubclass(w.category, SceneWarning)]})
    from processing.base.dataset import stage_seconds
    if tracking is not None:
        notes = sorted(set(notes) | set(tracking.pop("notes")))
    return {"id": payload["id"], "per_ping": ev["per_ping"], "tracking": tracking,
            "noise_histogram": ev["noise_histogram"], "figure": figure,
            "seconds": time.perf_counter() - t0,
            "stage_seconds": stage_seconds(tree),
            "notes": notes}


def _track_scores(tree, settings) -> dict:
    """Per setting, the tracks of the task's pings scored against the truth: {key: ndarray
    (n_settings,)} for every key of :data:`abacus.results.TRACK_KEYS` (NaN without truth, or
    where the mode has no 3-D positions), and ``notes``."""
    import processing
    from processing.base.dataset import DatasetError
    from processing.tracking.tracks import track_summary

    from abacus.results import TRACK_KEYS
    out = {k: np.full(len(settings), np.nan) for k in TRACK_KEYS}
    notes = []
    for i, st in enumerate(settings):
        try:
            summary = track_summary(processing.track(tree, st))["summary"]
        except DatasetError as exc:
            notes.append(f"no tracking scores: {str(exc).splitlines()[0]}")
            continue
        for k in TRACK_KEYS:
            v = summary.get(k)
            out[k][i] = np.nan if v is None else float(v)
    out["notes"] = notes
    return out


def _figure_bytes(tree, settings, ping) -> bytes:
    """The fan-beam image of the ping with its detections (thesis Appendix B), as PNG bytes."""
    import processing
    from abacus.figures.plots import count_figures
    counted = processing.count(tree, settings)
    with tempfile.TemporaryDirectory() as tmp:
        paths = count_figures(counted, tmp, pings=(0,), counts=False)
        return Path(paths[0]).read_bytes()


def _manifest(points, sweep, track_pings=None) -> dict:
    man = {"version": RESULTS_VERSION,
           "scene_sha256": [p.scene.sha256() for p in points],
           "settings": [p.settings.model_dump_json(by_alias=True) for p in points],
           "sweep": sweep.text if sweep else None}
    if track_pings:
        man["track_pings"] = int(track_pings)
    man["experiment"] = hashlib.sha256(json.dumps(man, sort_keys=True).encode()).hexdigest()
    return man


#: what an experiment folder may hold besides the manifest and the parts (its own outputs)
_OWN = {"experiment.json", PARTS, "results.nc", "results.zarr", "report.html", "figures"}


def _check_folder(out: Path, man: dict, restart: bool):
    """The output folder is empty, or holds this experiment (resume), or — with ``restart`` —
    an earlier run of an experiment to discard. Parts carry the experiment's identity, so a
    folder of another experiment is refused even when its manifest is gone or damaged."""
    if out.exists() and not out.is_dir():
        raise ExperimentError(f"-o {out}: is a file, expected a folder")
    if not out.exists():
        if not out.parent.exists():
            raise ExperimentError(f"-o {out}: the folder {out.parent} does not exist (create it first)")
        return
    from processing.base.atomic import TMP_MARK
    others = sorted(p.name for p in out.iterdir() if p.name not in _OWN and TMP_MARK not in p.name
                    and not p.name.startswith(".experiment.json") and not p.name.startswith(f".{PARTS}"))
    if others:
        raise ExperimentError(f"-o {out}: holds files that are not an experiment's ({', '.join(others[:3])}"
                              f"{', ...' if len(others) > 3 else ''}): choose an empty or new folder")
    if restart:
        return
    for name in (PARTS, "figures"):
        if (out / name).exists() and not (out / name).is_dir():
            raise ExperimentError(f"{out / name} is a file, where the experiment keeps a folder: "
                                  f"choose another -o, or --restart")
    path = out / "experiment.json"
    try:
        old = json.loads(path.read_text()) if path.exists() else None
    except (OSError, ValueError):
        old = None          # damaged: the parts say whose they are
    if isinstance(old, dict) and old.get("experiment") not in (None, man["experiment"]):
        raise ExperimentError(f"{out} holds another experiment (different scene, settings or sweep): "
                              f"choose another -o, or --restart to discard it")
    parts = out / PARTS
    if parts.is_dir():
        from abacus.results import part_state
        for f in sorted(parts.glob("*.npz"))[:20]:   # a sample is enough to tell whose they are
            if part_state(f, man["experiment"]) == "foreign":
                raise ExperimentError(f"{out} holds parts of another experiment ({f.name}): choose "
                                      f"another -o, or --restart to discard them")


def _start_folder(out: Path, man: dict, restart: bool):
    """Create or reset the folder and write the manifest (after every check has passed)."""
    from processing.base.atomic import remove_path, remove_stale
    if restart:
        for name in _OWN:
            remove_path(out / name)
    out.mkdir(exist_ok=True)
    (out / PARTS).mkdir(exist_ok=True)
    remove_stale(out / PARTS)
    remove_stale(out)
    write_text_atomic(out / "experiment.json", json.dumps(man, indent=1))


# ------------------------------------------------------------------ running
def run_experiment(scene, out_dir, *, pings=None, sweep: Sweep | None = None, workers: int | None = None,
                   scheduler: str | None = None, figure_pings: int = 2, fmt: str = "netcdf",
                   restart: bool = False, progress=None, report: bool = True,
                   track_pings: int | None = None) -> Path:
    """Run (or resume) an experiment and write its dataset and report.

    Parameters
    ----------
    scene : Scene
    out_dir : str or Path
        Output folder: ``results.nc`` (or ``.zarr``), ``report.html``, ``figures/``, ``parts/``.
    pings : int or iterable of int, optional
        Default the scene's pings; an int ``n``: the scene's first ``n`` pings (as
        :func:`acoustics.simulate` reads it).
    sweep : Sweep, optional
    workers : int, optional
        Local Dask workers (processes); 0 runs in this process without Dask; default the
        fastest layout for this machine (:func:`plan_workers`).
    scheduler : str, optional
        Address of an existing Dask scheduler (its workers need abacus installed). Workers
        and schedulers need the extra ``experiment`` (dask[distributed]); in process, nothing.
    figure_pings : int
        How many of the first pings get a fan-beam figure with detections.
    fmt : {"netcdf", "zarr"}
        Zarr needs the extra ``zarr``.
    restart : bool
        Discard the parts of an earlier run in ``out_dir``.
    progress : callable(done, total), optional
    track_pings : int, optional
        Track runs of this many consecutive pings (each run one task, the last one possibly
        shorter) and score them as ``abacus track`` does: HOTA, DetA, AssA, LocA, IDF1, MOTA,
        MOTP and the passages counted and true per run, and per setting the nMAE of the track
        counts over the runs (Σ|counted − true| / Σ true; Kay et al. 2022). At least 2.

    Returns
    -------
    Path
        The results dataset.

    Raises
    ------
    ExperimentError
        Bad arguments, or a folder holding another experiment.
    processing.base.extras.MissingExtra
        An extra this run needs (Dask, Zarr) is not installed.
    """
    out = Path(out_dir)
    n_workers, threads = plan_workers(workers, scheduler)   # a bad count fails before any write
    if isinstance(pings, int) and not isinstance(pings, bool):
        pings = range(scene.pings.first, scene.pings.first + max(pings, 0))
    pings = list(range(scene.pings.first, scene.pings.first + scene.pings.count)) if pings is None else list(pings)
    if not pings:
        raise ExperimentError("an experiment needs at least one ping")
    if fmt not in ("netcdf", "zarr"):
        raise ExperimentError(f"format must be netcdf or zarr, got {fmt!r}")
    if track_pings is not None and (isinstance(track_pings, bool) or not isinstance(track_pings, (int, np.integer))
                                    or not 2 <= track_pings <= len(pings)):
        raise ExperimentError(f"--track-pings must be a whole number of pings from 2 to the "
                              f"experiment's {len(pings)}, got {track_pings!r}")
    # the optional extras this run needs, checked before any work (MissingExtra names them)
    from processing.base.extras import require
    if n_workers or scheduler:
        require("dask.distributed", "an experiment on Dask workers (--workers, --scheduler)")
    if fmt == "zarr":
        require("zarr", "an experiment's results as Zarr")
    points = experiment_plan(scene, sweep)
    man = _manifest(points, sweep, track_pings)
    _check_folder(out, man, restart)
    # the scheduler is reached before the folder is made: one that does not answer leaves nothing
    client = _connect(scheduler) if scheduler else None
    try:
        _start_folder(out, man, restart)
    except BaseException:
        if client is not None:
            client.close()
        raise
    parts = out / PARTS
    tasks = _tasks(points, pings, sweep, track_pings)
    from abacus.results import part_state
    states = {t[0]: part_state(parts / f"{t[0]}.npz", man["experiment"]) for t in tasks}
    todo = [t for t in tasks if states[t[0]] != "ok"]
    damaged = sum(s == "damaged" for s in states.values())
    texts = {j: p.scene.resolved_text() for j, p in enumerate(points)}
    source = str(scene.source_path) if scene.source_path else None
    figs = set(pings[:max(0, figure_pings)])
    payloads = [{"id": tid, "scene_text": texts[j], "source": source, "pings": ps, "threads": threads,
                 "settings": [points[i].settings.model_dump_json(by_alias=True) for i in idx],
                 "figure": j == 0 and ps[0] in figs, "track": bool(track_pings)}
                for tid, j, ps, idx in todo]
    t_start = time.perf_counter()
    done = len(tasks) - len(todo)
    if progress:
        progress(done, len(tasks))
    for res in _execute(payloads, n_workers, scheduler, threads, client=client):
        save_part(parts, res, experiment=man["experiment"])
        done += 1
        if progress:
            progress(done, len(tasks))
    wall = time.perf_counter() - t_start
    attrs = {
        "title": f"abacus experiment: {scene.name}", "results_version": RESULTS_VERSION,
        "scene_text": scene.resolved_text(), "scene_sha256": scene.sha256(),
        "scene_file": str(scene.source_path or ""), "sweep": sweep.text if sweep else "",
        "sweep_key": sweep.key if sweep else "", "sweep_path": sweep.path if sweep else "",
        "sweep_processing_only": int(sweep.processing_only) if sweep else 1,
        "settings_json": json.dumps([json.loads(p.settings.model_dump_json(by_alias=True)) for p in points]),
        "wall_seconds": wall, "workers": n_workers if not scheduler else -1,
        "threads_per_task": threads,
        "scheduler": scheduler or ("local" if n_workers else "in-process"),
        "tasks_run": len(todo), "tasks_resumed": len(tasks) - len(todo),
        "track_pings": int(track_pings or 0),
        "parts_recomputed_damaged": damaged}
    ds = assemble_results(labels=[p.label for p in points], values=[p.value for p in points],
                          pings=pings, tasks=tasks, parts=parts, attrs=attrs,
                          experiment=man["experiment"])
    figdir = out / "figures"
    figdir.mkdir(exist_ok=True)
    for tid, j, ps, _ in tasks:
        if j == 0 and ps[0] in figs:
            fig = load_part(parts / f"{tid}.npz", experiment=man["experiment"])["figure"]
            if fig:
                write_bytes_atomic(figdir / f"detections_ping{ps[0]}.png", fig)
    path = out / ("results.zarr" if fmt == "zarr" else "results.nc")
    write_dataset(ds, path, fmt=fmt, chunk_dim="ping")
    if report:
        from abacus.report import write_report
        write_report(ds, out)
    return path


#: on machines with at most this many usable cores the default runs in process: measured here
#: (2 cores; docs/performance.md, "experiment") faster than a local cluster, which re-pays
#: imports and kernel loading in every worker and splits cores that the in-process run's
#: multi-threaded kernels already use
AUTO_IN_PROCESS_MAX_CORES = 2


def plan_workers(workers: int | None, scheduler: str | None = None):
    """(local workers, threads per task) for an experiment.

    ``workers=None`` (the default) picks the fastest layout for this machine: in process with
    every core for the kernels up to :data:`AUTO_IN_PROCESS_MAX_CORES` cores, else a local
    cluster of two-thread workers (cores / 2 of them). ``workers=0``: in process; ``k > 0``: k
    workers sharing the cores. With a scheduler the workers are the cluster's, one thread a task.

    Raises
    ------
    ExperimentError
        A negative number of workers.
    """
    cores = usable_cores()
    if scheduler:
        return -1, 1
    if workers is None:
        if cores <= AUTO_IN_PROCESS_MAX_CORES:
            return 0, cores
        return cores // 2, 2
    workers = int(workers)
    if workers < 0:
        raise ExperimentError(f"--workers must be >= 0, got {workers}")
    if workers == 0:
        return 0, cores
    return workers, max(1, cores // workers)


#: seconds to wait for a Dask scheduler given by --scheduler to answer
SCHEDULER_TIMEOUT_S = 10.0


def _connect(scheduler: str):
    """A Dask client of the scheduler at ``scheduler``, or one line saying it did not answer.

    Raises
    ------
    ExperimentError
        No scheduler answered at that address within :data:`SCHEDULER_TIMEOUT_S` (or the
        address is not one), with nothing written.
    """
    import logging

    from dask.distributed import Client
    logging.getLogger("distributed").setLevel(logging.CRITICAL)
    try:
        return Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
    except (OSError, ValueError, TypeError, TimeoutError) as exc:
        text = str(exc).splitlines()[0][:160] if str(exc).strip() else exc.__class__.__name__
        raise ExperimentError(f"--scheduler {scheduler}: no Dask scheduler answered there ({text}); "
                              f"nothing was written: start the scheduler (dask scheduler) or give its "
                              f"address as tcp://HOST:PORT") from None


def _execute(payloads, n_workers, scheduler, threads=1, client=None):
    """Yield task results as they finish (in-process, a local cluster, or a scheduler; ``client``
    a client already connected to it)."""
    if not payloads:
        if client is not None:
            client.close()
        return
    if not scheduler and n_workers == 0:
        for p in payloads:
            yield run_task(p)
        return
    import logging

    from dask.distributed import Client, LocalCluster, as_completed
    logging.getLogger("distributed").setLevel(logging.ERROR)
    cluster = None
    if scheduler:
        client = client if client is not None else _connect(scheduler)
    else:
        # one task at a time per worker; its kernels, FFTs and BLAS use the worker's share of
        # the cores and no more (oversubscribed threads were 2–12x slower on small pings)
        limit = str(threads)
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR,
                               env={"OMP_NUM_THREADS": limit, "OPENBLAS_NUM_THREADS": limit,
                                    "MKL_NUM_THREADS": limit, "NUMBA_NUM_THREADS": limit})
        client = Client(cluster)
    try:
        futures = [client.submit(run_task, p, key=f"abacus-{p['id']}-{hashlib.sha1(p['scene_text'].encode()).hexdigest()[:8]}",
                                 pure=False) for p in payloads]
        for fut in as_completed(futures):
            yield fut.result()
            fut.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
