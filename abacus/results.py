"""An experiment's results on disk: one part per finished task, and the results dataset.

A *part* holds what one task (one simulated ping, evaluated under one or more settings) returned:
per-ping numbers per setting, the noise histogram, timings, notes and an optional PNG. Parts are
written atomically, so a resumed experiment only ever sees whole ones. :func:`assemble_results`
turns the parts into the results dataset (setting x ping) with the chapter-6 summaries; the
orchestration (what to run, where) lives in :mod:`abacus.experiment`.
"""
from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.atomic import write_bytes_atomic
from abacus.evaluate import NOISE_BINS, PER_PING_KEYS

__all__ = ["save_part", "load_part", "part_state", "PartError", "assemble_results", "TRACK_KEYS"]

#: what a tracked run of pings gives per setting (``abacus experiment --track-pings``): the
#: passages counted and true, and the scores of ``abacus track`` (processing/tracking/scores.py)
TRACK_KEYS = ("counted_passages", "true_passages", "hota", "deta", "assa", "loca", "idf1", "mota", "motp")


class PartError(ValueError):
    """A part that cannot be used: damaged (recompute it) or of another experiment."""


def _digest(arrays: dict) -> str:
    h = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k])
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_part(parts: Path, res: dict, *, experiment: str = "") -> Path:
    """Write one task's result (``res`` from the task runner) as ``parts/<id>.npz``, atomically,
    with the experiment's identity (a hash of its scenes, settings and sweep) and a checksum of
    its contents."""
    arrays = {f"pp_{k}": np.atleast_2d(np.asarray(v, float).T).T for k, v in res["per_ping"].items()}
    arrays.update({f"tr_{k}": np.asarray(v, float) for k, v in (res.get("tracking") or {}).items()})
    arrays.update(noise_histogram=np.atleast_2d(np.asarray(res["noise_histogram"])),
                  seconds=np.asarray(res["seconds"]),
                  stage_seconds=np.asarray(json.dumps(res["stage_seconds"])),
                  notes=np.asarray(json.dumps(res["notes"])),
                  figure=np.frombuffer(res["figure"], np.uint8),
                  experiment=np.asarray(experiment))
    buf = io.BytesIO()
    np.savez(buf, checksum=np.asarray(_digest(arrays)), **arrays)
    return write_bytes_atomic(Path(parts) / f"{res['id']}.npz", buf.getvalue())


def load_part(path: Path, *, experiment: str | None = None) -> dict:
    """One part as written by :func:`save_part`, verified.

    Raises
    ------
    PartError
        Unreadable, truncated, its checksum wrong (``damaged``), or written by another experiment
        than ``experiment`` (``foreign``); ``PartError.args[1]`` says which.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:
        raise PartError(f"{path.name}: unreadable ({exc.__class__.__name__})", "damaged") from None
    checksum = str(arrays.pop("checksum", ""))
    if not checksum or _digest(arrays) != checksum:
        raise PartError(f"{path.name}: its checksum does not match its contents", "damaged")
    if experiment is not None and str(arrays.get("experiment", "")) != experiment:
        raise PartError(f"{path.name}: written by another experiment", "foreign")
    try:
        # per setting and ping (n_settings, n_pings); a part of one ping before runs were
        # tracked held (n_settings,)
        return {"per_ping": {k[3:]: arrays[k].reshape(arrays[k].shape[0], -1) for k in arrays
                             if k.startswith("pp_")},
                "tracking": {k[3:]: arrays[k] for k in arrays if k.startswith("tr_")} or None,
                "noise_histogram": np.atleast_2d(arrays["noise_histogram"]), "seconds": float(arrays["seconds"]),
                "stage_seconds": json.loads(str(arrays["stage_seconds"])),
                "notes": json.loads(str(arrays["notes"])), "figure": arrays["figure"].tobytes()}
    except (KeyError, ValueError) as exc:
        raise PartError(f"{path.name}: incomplete ({exc})", "damaged") from None


def part_state(path: Path, experiment: str) -> str:
    """``"ok"``, ``"missing"``, ``"damaged"`` or ``"foreign"`` for a part file."""
    if not path.exists():
        return "missing"
    try:
        load_part(path, experiment=experiment)
    except PartError as exc:
        return exc.args[1]
    return "ok"


def assemble_results(*, labels, values, pings, tasks, parts: Path, attrs: dict,
                     experiment: str | None = None) -> xr.Dataset:
    """The results dataset of an experiment from its parts.

    Parameters
    ----------
    labels : sequence of str, length n_settings
        Setting labels ("scene", "threshold=600", ...).
    values : sequence of float, length n_settings
        Sweep value of each setting (NaN for the scene as written).
    pings : sequence of int, length n_pings
    tasks : sequence of (task id, point index, pings, setting indices)
    parts : Path
        Folder of the parts.
    attrs : dict
        Root attributes (scene text and hash, sweep, settings, timing).

    Returns
    -------
    xarray.Dataset
        Per-ping numbers (setting, ping), the noise histogram (ping, noise_bin), task times,
        and per-setting means, standard deviations, the nMAE of the per-ping counts before and
        after interferometry (``count_nmae_before``, ``count_nmae_after``) and the TS estimate.
        Tracked runs (parts with tracking scores) add per (setting, run) every key of
        :data:`TRACK_KEYS` along ``run`` (its first ping in ``run_first_ping``), and per
        setting ``track_count_nmae`` (Σ|counted − true| / Σ true over the runs) and the mean
        of each score over the runs.
    """
    n_set, n_p = len(labels), len(pings)
    col = {p: i for i, p in enumerate(pings)}
    data = {k: np.full((n_set, n_p), np.nan) for k in PER_PING_KEYS}
    hist = np.zeros((n_p, NOISE_BINS.size - 1))
    seconds = np.zeros(n_p)
    stages: dict = {}
    notes: dict = {}
    runs = [ps[0] for _, j, ps, _ in tasks if j == 0]
    run_of = {first: i for i, first in enumerate(runs)}
    tracked = {k: np.full((n_set, len(runs)), np.nan) for k in TRACK_KEYS}
    any_tracked = False
    for tid, j, ps, idx in tasks:
        part = load_part(Path(parts) / f"{tid}.npz", experiment=experiment)
        cols = [col[p] for p in ps]
        for k in PER_PING_KEYS:
            data[k][np.ix_(idx, cols)] = part["per_ping"][k]
        if j == 0:
            hist[cols] = part["noise_histogram"]
        seconds[cols] += part["seconds"] / len(cols)     # a run's time shared by its pings
        if part["tracking"]:
            any_tracked = True
            for k in TRACK_KEYS:
                tracked[k][idx, run_of[ps[0]]] = part["tracking"][k]
        for s, t in part["stage_seconds"].items():
            stages[s] = stages.get(s, 0.0) + t
        for n in part["notes"]:
            notes[n] = notes.get(n, 0) + 1
    na = {"nan_means": "does not apply to this setting or ping (no truth, no noise estimate, no "
                        "calibration, nothing counted)"}
    ds = xr.Dataset(
        {k: xr.DataArray(v, dims=("setting", "ping"), attrs=dict(na)) for k, v in data.items()},
        coords={"setting": np.arange(n_set),
                "setting_label": ("setting", np.array(list(labels), dtype=str)),
                "sweep_value": ("setting", np.array(list(values), float)),
                "ping": np.asarray(pings, np.int64),
                "noise_bin_edge": ("noise_bin_edge", NOISE_BINS)})
    ds["noise_histogram"] = xr.DataArray(hist, dims=("ping", "noise_bin"), attrs={
        "long_name": "counts of |I| / sigma_hat over the noise cells, per ping (setting 0)",
        "bin_edges": "noise_bin_edge"})
    ds["task_seconds"] = xr.DataArray(seconds, dims="ping", attrs={"units": "s"})
    units = {"density_per_m3": "m^-3", "true_density_per_m3": "m^-3", "threshold_counts": "ADC counts",
             "noise_sigma_counts": "ADC counts", "s_v_per_m": "m^-1", "sigma_bs_m2": "m^2",
             "true_sigma_bs_m2": "m^2"}
    for k, u in units.items():
        ds[k].attrs["units"] = u
    # per setting: the chapter-6 summaries
    for k in ("error_before", "error_after", "count_before", "count_after", "true_in_volume",
              "density_per_m3", "true_density_per_m3", "threshold_counts"):
        ds[f"{k}_mean"] = ds[k].mean("ping")
        ds[f"{k}_std"] = ds[k].std("ping")
    # nMAE of the per-ping counts (Kay et al. 2022): Σ|count − true| / Σ true over the pings, so
    # over- and under-counts of single pings do not cancel as they do in the mean error. The
    # tracking scores (MOTA, IDF1, HOTA, nMAE of track counts) need a run of consecutive pings,
    # not the independent pings an experiment's tasks are: `abacus track --json` gives them
    from processing.tracking.hota import nmae
    for when in ("before", "after"):
        c, t = ds[f"count_{when}"].values, ds["true_in_volume"].values
        vals = []
        for i in range(n_set):
            ok = np.isfinite(c[i]) & np.isfinite(t[i])
            vals.append(nmae(c[i][ok], t[i][ok]) if ok.any() else np.nan)
        ds[f"count_nmae_{when}"] = xr.DataArray(np.array(vals, float), dims="setting", attrs={
            "long_name": f"nMAE of the per-ping counts {when} interferometry: "
                         "sum |count - true| / sum true over the pings", "units": "1",
                         "nan_means": "no truth, or no fish in the volume in any ping"})
    if any_tracked:
        _add_tracking(ds, tracked, runs)
    with np.errstate(divide="ignore", invalid="ignore"):
        sv, dens = ds["s_v_per_m"].sum("ping", skipna=True), ds["density_per_m3"].sum("ping")
        ds["ts_estimate_db"] = 10 * np.log10(xr.where(dens > 0, sv / dens, np.nan).where(sv > 0))
        ds["ts_true_db"] = 10 * np.log10(ds["true_sigma_bs_m2"].mean("ping", skipna=True))
    ds["ts_estimate_db"].attrs = {"units": "dB re 1 m^2",
                                  "long_name": "10 log10(sum s_v / sum counted density) over the pings"}
    ds["ts_true_db"].attrs = {"units": "dB re 1 m^2",
                              "long_name": "10 log10 of the mean sigma_bs of the true targets in the volume"}
    for k in ds.data_vars:   # summaries of not-applicable values stay not applicable
        if ds[k].dtype.kind == "f" and k not in ("noise_histogram", "task_seconds"):
            ds[k].attrs.setdefault("nan_means", na["nan_means"])
    ds.attrs.update({**attrs, "stage_seconds_json": json.dumps(stages),
                     "notes": "; ".join(f"{n} ({c} task{'s' if c > 1 else ''})"
                                        for n, c in sorted(notes.items()))})
    return ds


def _add_tracking(ds: xr.Dataset, tracked: dict, runs: list) -> None:
    """The tracked runs' scores along ``run``, and per setting their nMAE and means."""
    from processing.tracking.hota import nmae
    ds.coords["run_first_ping"] = ("run", np.asarray(runs, np.int64))
    long = {"counted_passages": "passages through the counting volume counted as tracks",
            "true_passages": "fish that passed through the counting volume",
            "hota": "HOTA (Luiten et al. 2021)", "deta": "HOTA's detection accuracy",
            "assa": "HOTA's association accuracy", "loca": "HOTA's localisation accuracy",
            "idf1": "IDF1", "mota": "MOTA", "motp": "MOTP: mean distance of matched track points"}
    for k, v in tracked.items():
        ds[f"run_{k}"] = xr.DataArray(v, dims=("setting", "run"), attrs={
            "long_name": long[k], "units": "m" if k == "motp" else "1",
            "nan_means": "no truth, no passage, or no 3-D positions in this run"})
    vals = []
    for c, t in zip(tracked["counted_passages"], tracked["true_passages"]):
        ok = np.isfinite(c) & np.isfinite(t)
        vals.append(nmae(c[ok], t[ok]) if ok.any() else np.nan)
    ds["track_count_nmae"] = xr.DataArray(np.array(vals, float), dims="setting", attrs={
        "long_name": "nMAE of the track counts over the runs: sum |counted - true| / sum true "
                     "(Kay et al. 2022); over- and under-counts of runs do not cancel",
        "units": "1", "nan_means": "no truth, or no passage in any run"})
    # a run without a fish passing and without a track scores HOTA 0 and LocA 1 by the
    # convention of TrackEval: nothing to score, left out of the means (as benchmarks/density.py)
    empty = (tracked["true_passages"] == 0) & (tracked["counted_passages"] == 0)
    for k in ("hota", "deta", "assa", "loca", "idf1", "mota", "motp"):
        v = np.where(empty, np.nan, tracked[k])
        m = np.array([row[np.isfinite(row)].mean() if np.isfinite(row).any() else np.nan
                      for row in v], float)
        ds[f"{k}_mean"] = xr.DataArray(m, dims="setting", attrs={
            "long_name": f"mean over the runs with a fish or a track passing of {long[k]}",
            "units": "m" if k == "motp" else "1",
            "nan_means": "no run with a fish or a track passing the counting volume"})
