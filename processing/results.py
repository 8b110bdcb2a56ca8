"""An experiment's results on disk: one part per finished task, and the results dataset.

A *part* holds what one task (one simulated ping, evaluated under one or more settings) returned:
per-ping numbers per setting, the noise histogram, timings, notes and an optional PNG. Parts are
written atomically, so a resumed experiment only ever sees whole ones. :func:`assemble_results`
turns the parts into the results dataset (setting x ping) with the chapter-6 summaries; the
orchestration (what to run, where) lives in :mod:`acoustics.experiment`.
"""
from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import xarray as xr

from .atomic import write_bytes_atomic
from .evaluate import NOISE_BINS, PER_PING_KEYS

__all__ = ["save_part", "load_part", "assemble_results"]


def save_part(parts: Path, res: dict) -> Path:
    """Write one task's result (``res`` from the task runner) as ``parts/<id>.npz``, atomically."""
    buf = io.BytesIO()
    arrays = {f"pp_{k}": v for k, v in res["per_ping"].items()}
    np.savez(buf, noise_histogram=res["noise_histogram"], seconds=res["seconds"],
             stage_seconds=json.dumps(res["stage_seconds"]), notes=json.dumps(res["notes"]),
             figure=np.frombuffer(res["figure"], np.uint8), **arrays)
    return write_bytes_atomic(Path(parts) / f"{res['id']}.npz", buf.getvalue())


def load_part(path: Path) -> dict:
    """One part as written by :func:`save_part`."""
    with np.load(path) as z:
        return {"per_ping": {k[3:]: z[k] for k in z.files if k.startswith("pp_")},
                "noise_histogram": z["noise_histogram"], "seconds": float(z["seconds"]),
                "stage_seconds": json.loads(str(z["stage_seconds"])),
                "notes": json.loads(str(z["notes"])), "figure": z["figure"].tobytes()}


def assemble_results(*, labels, values, pings, tasks, parts: Path, attrs: dict) -> xr.Dataset:
    """The results dataset of an experiment from its parts.

    Parameters
    ----------
    labels : sequence of str, length n_settings
        Setting labels ("scene", "threshold=600", ...).
    values : sequence of float, length n_settings
        Sweep value of each setting (NaN for the scene as written).
    pings : sequence of int, length n_pings
    tasks : sequence of (task id, point index, ping, setting indices)
    parts : Path
        Folder of the parts.
    attrs : dict
        Root attributes (scene text and hash, sweep, settings, timing).

    Returns
    -------
    xarray.Dataset
        Per-ping numbers (setting, ping), the noise histogram (ping, noise_bin), task times,
        and per-setting means, standard deviations and the TS estimate.
    """
    n_set, n_p = len(labels), len(pings)
    col = {p: i for i, p in enumerate(pings)}
    data = {k: np.full((n_set, n_p), np.nan) for k in PER_PING_KEYS}
    hist = np.zeros((n_p, NOISE_BINS.size - 1))
    seconds = np.zeros(n_p)
    stages: dict = {}
    notes: dict = {}
    for tid, j, p, idx in tasks:
        part = load_part(Path(parts) / f"{tid}.npz")
        for k in PER_PING_KEYS:
            data[k][idx, col[p]] = part["per_ping"][k]
        if j == 0:
            hist[col[p]] = part["noise_histogram"]
        seconds[col[p]] += part["seconds"]
        for s, t in part["stage_seconds"].items():
            stages[s] = stages.get(s, 0.0) + t
        for n in part["notes"]:
            notes[n] = notes.get(n, 0) + 1
    ds = xr.Dataset(
        {k: xr.DataArray(v, dims=("setting", "ping")) for k, v in data.items()},
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
    with np.errstate(divide="ignore", invalid="ignore"):
        sv, dens = ds["s_v_per_m"].sum("ping", skipna=True), ds["density_per_m3"].sum("ping")
        ds["ts_estimate_db"] = 10 * np.log10(xr.where(dens > 0, sv / dens, np.nan).where(sv > 0))
        ds["ts_true_db"] = 10 * np.log10(ds["true_sigma_bs_m2"].mean("ping", skipna=True))
    ds["ts_estimate_db"].attrs = {"units": "dB re 1 m^2",
                                  "long_name": "10 log10(sum s_v / sum counted density) over the pings"}
    ds["ts_true_db"].attrs = {"units": "dB re 1 m^2",
                              "long_name": "10 log10 of the mean sigma_bs of the true targets in the volume"}
    ds.attrs.update({**attrs, "stage_seconds_json": json.dumps(stages),
                     "notes": "; ".join(f"{n} ({c} task{'s' if c > 1 else ''})"
                                        for n, c in sorted(notes.items()))})
    return ds
