"""Single targets: which detections are one fish's own echo, with its target strength.

Echosounder practice (Echoview's single-target detection, Sonar5's) keeps a detection as a
single target when it is not another echo's sidelobe and its beam-compensated TS is above a
threshold. Here a detection of a dataset is a single target when

* no stronger detection of its ping lies in its resolution cell, or within 2.5 range cells and
  ``sidelobe_db`` stronger (:func:`single_targets`: range and azimuth sidelobes, grating ghosts);
* its compensated TS is at least ``min_ts_db``, or NaN (beyond the compensable beam, where no TS
  can be given but the echo is real): far range sidelobes of the Hamming range window (≈ −80 dB)
  and multipath echoes fall below it.

:func:`single_target_table` gives every detection its TS (uncompensated and compensated for the
two-way beam pattern at its located angles, processing/backscatter/target_strength.py) and the verdict;
:func:`write_single_targets_csv` exports the single targets with columns close to Echoview's
single-target export.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.dataset import DatasetError

__all__ = ["single_targets", "single_target_table", "write_single_targets_csv", "SINGLE_TARGET_COLUMNS"]


def single_targets(ping_rows, range_m, azimuth_rad, amplitude, *, range_resolution_m: float,
                   azimuth_resolution_rad: float, sidelobe_db: float):
    """Which detections are single targets rather than another's sidelobe or a second peak of
    the same echo.

    A strong echo is detected several times in its ping: at its own cell, in its range sidelobes
    (±1–2 cells, 40–50 dB down) and at the same range in azimuth sidelobes and grating-lobe
    ghosts (20–35 dB down for ABACUS). A detection is kept unless a stronger one of the same ping
    lies within 2.5 range cells and more than ``sidelobe_db`` stronger, or in the same resolution
    cell (within one range resolution and 1.5 azimuth cells). Two fish a range cell or more apart
    are both kept: in a school they are often unresolved in azimuth (2.4° is 0.75 m at 18 m) but
    resolved in range (6.7 cm). A weaker fish at the same range as a much stronger one is lost
    with the sidelobes: the price of not tracking ghosts.

    Parameters
    ----------
    ping_rows : array_like of int, shape (n,)
    range_m, azimuth_rad, amplitude : array_like, shape (n,)
        Range (m), azimuth (rad), image peak (counts).
    range_resolution_m, azimuth_resolution_rad, sidelobe_db : float

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    rows = np.asarray(ping_rows, int)
    r = np.asarray(range_m, float)
    az = np.asarray(azimuth_rad, float)
    a = np.asarray(amplitude, float)
    keep = np.ones(rows.size, bool)
    if sidelobe_db <= 0:
        return keep
    ratio = 10.0 ** (sidelobe_db / 20.0)
    for p in np.unique(rows):
        k = np.flatnonzero(rows == p)
        # pairs (i stronger than j) of this ping: j goes if any stronger i is near it in range
        # and either in its cell or far above it
        stronger = a[k][:, None] > a[k][None, :]
        near = np.abs(r[k][:, None] - r[k][None, :]) <= 2.5 * range_resolution_m
        same_cell = ((np.abs(az[k][:, None] - az[k][None, :]) <= 1.5 * azimuth_resolution_rad)
                     & (np.abs(r[k][:, None] - r[k][None, :]) <= range_resolution_m))
        far_above = a[k][:, None] > ratio * a[k][None, :]
        keep[k] = ~np.any(stronger & near & (same_cell | far_above), axis=0)
    return keep


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
    from processing.backscatter.calibration import calibration_of
    from processing.records import DETECTIONS_GROUP, PROCESSING_GROUP, detections_of, resolve_settings
    from processing.backscatter.target_strength import beam_pattern_of, target_strength_db
    st = resolve_settings(tree, settings)
    det = detections_of(tree)
    da = tree[DETECTIONS_GROUP].ds.attrs
    if "range_resolution_m" not in da:
        da = tree[PROCESSING_GROUP].ds.attrs
    n = det.sizes.get("detection", len(det["range_m"]))
    sonar_xyz = np.stack([det[f"{a}_m"].values for a in "xyz"], -1)
    try:     # recorded data may lack a calibration or the element geometry: TS is then NaN
        cal = calibration_of(tree)
        ts_u, ts_c, pat = target_strength_db(det["amplitude"].values, det["range_m"].values, sonar_xyz,
                                             gain_counts_m=cal.gain_counts_m,
                                             absorption_db_per_m=cal.absorption_db_per_m,
                                             pattern=beam_pattern_of(tree))
    except DatasetError:
        ts_u = ts_c = pat = np.full(n, np.nan)
    single = single_targets(det["ping"].values, det["range_m"].values, det["azimuth_rad"].values,
                            det["amplitude"].values, range_resolution_m=float(da["range_resolution_m"]),
                            azimuth_resolution_rad=float(da["azimuth_resolution_rad"]),
                            sidelobe_db=st.track.sidelobe_db)
    single &= ~(ts_c < st.track.min_ts_db)
    out = det.assign(ts_uncomp_db=(det["range_m"].dims, ts_u), ts_comp_db=(det["range_m"].dims, ts_c),
                     beam_pattern_db=(det["range_m"].dims, pat),
                     single_target=(det["range_m"].dims, single))
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
