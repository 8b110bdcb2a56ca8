"""The single-target table of a dataset and its CSV export (Echoview-like columns).

The verdict and TS of each detection come from the chain
(:meth:`processing.pipeline.RecordChain.single_targets`, the rules in
:mod:`processing.backscatter.single_targets`); this module gives them as a table and a file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

__all__ = ["single_target_table", "write_single_targets_csv", "SINGLE_TARGET_COLUMNS"]


def single_target_table(tree: xr.DataTree, settings=None) -> xr.Dataset:
    """Target strength and single-target verdict of every detection of a dataset.

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset with /Processing/Detections (see :func:`processing.detect`).
    settings : ProcessingSettings, dict or path, optional
        ``track.sidelobe_db`` and ``track.min_ts_db`` set the rules.

    Returns
    -------
    xarray.Dataset
        The detections table (dim ``detection``) with ``ts_uncomp_db`` and ``ts_comp_db``
        (dB re 1 m²; NaN without a calibration, ts_comp NaN beyond the compensable beam),
        ``beam_pattern_db`` (two-way, dB re axis) and ``single_target`` (bool).
    """
    from processing.base.contract import DETECTIONS_GROUP
    from processing.pipeline import RecordChain
    chain = RecordChain(tree, settings)
    detected = chain.detected()
    columns = chain.single_targets(detected)
    tree = chain.tree
    ds = tree[DETECTIONS_GROUP].ds if detected.detections is None else None
    if ds is not None:       # the stored table, with its units and attributes
        det = ds[[k for k in ds.data_vars if ds[k].dims == ("detection",)]]
    else:
        det = xr.Dataset({k: ("detection", np.asarray(v)) for k, v in detected.table.items()})
    det = det.assign({k: det[k].astype(bool) for k in ("in_span", "in_volume", "elevation_clipped")
                      if k in det})
    dims = ("detection",)
    out = det.assign(ts_uncomp_db=(dims, columns["ts_uncomp_db"]), ts_comp_db=(dims, columns["ts_comp_db"]),
                     beam_pattern_db=(dims, columns["beam_pattern_db"]),
                     single_target=(dims, columns["single_target"]))
    out["ts_uncomp_db"].attrs.update(units="dB re 1 m2", long_name="TS taken on axis",
                                     nan_means="no calibration in the dataset")
    out["ts_comp_db"].attrs.update(units="dB re 1 m2", long_name="TS compensated for the two-way "
                                   "beam pattern at the located angles",
                                   nan_means="no calibration, or the pattern there below −20 dB")
    out["beam_pattern_db"].attrs.update(units="dB re axis", long_name="two-way beam pattern at the located angles")
    return out


#: CSV column -> detections variable (or a derived quantity): Echoview's single-target export
#: names where one exists (Ping_index, Target_range, TS_comp, TS_uncomp, angles, position)
SINGLE_TARGET_COLUMNS = (
    ("Ping_index", "ping_index"), ("Target_range", "range_m"), ("TS_comp", "ts_comp_db"),
    ("TS_uncomp", "ts_uncomp_db"), ("Beam_pattern_db", "beam_pattern_db"),
    ("Angle_azimuth_deg", "azimuth_rad"), ("Angle_elevation_deg", "elevation_rad"),
    ("Target_x_m", "x_m"), ("Target_y_m", "y_m"), ("Target_z_m", "z_m"),
    ("Target_world_x_m", "world_x_m"), ("Target_world_y_m", "world_y_m"),
    ("Target_world_z_m", "world_z_m"), ("SNR_db", "snr_db"))


def write_single_targets_csv(tree: xr.DataTree, path, settings=None) -> Path:
    """Write the single targets (one row each; columns :data:`SINGLE_TARGET_COLUMNS`, angles in
    degrees, lengths in m, TS in dB re 1 m², empty where NaN) as CSV, atomically."""
    import csv

    from processing.base.atomic import staged
    table = single_target_table(tree, settings)
    keep = table["single_target"].values.astype(bool)
    cols = [(name, var) for name, var in SINGLE_TARGET_COLUMNS if var in table]
    values = {}
    for name, var in cols:
        v = table[var].values[keep]
        values[name] = np.degrees(v) if var.endswith("_rad") else v
    path = Path(path)
    with staged(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([name for name, _ in cols])
        for i in range(int(keep.sum())):
            row = []
            for name, _ in cols:
                x = values[name][i]
                if np.issubdtype(np.asarray(x).dtype, np.integer):
                    row.append(int(x))
                else:
                    row.append("" if not np.isfinite(x) else f"{float(x):.9g}")
            w.writerow(row)
    return path
