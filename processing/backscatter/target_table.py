"""The single-target tables of a dataset and their CSV exports (Echoview-like columns).

Two verdicts, two tables:

* :func:`single_targets` (``processing.single_targets``, ``abacus targets``): single-target
  detection by the echosounder criteria (:mod:`processing.backscatter.echo_criteria`, the
  ``single_target`` settings), every candidate a row with the rule that rejected it;
* :func:`single_target_table` (``abacus count --targets-csv``, the tracker's input): the
  sidelobe rule and ``track.min_ts_db`` (:mod:`processing.backscatter.single_targets`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

__all__ = ["single_target_table", "write_single_targets_csv", "SINGLE_TARGET_COLUMNS", "single_targets",
           "write_targets_csv", "TARGET_COLUMNS"]


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
    table = single_target_table(tree, settings)
    return _write_rows_csv(table, SINGLE_TARGET_COLUMNS, table["single_target"].values.astype(bool), path)


def _write_rows_csv(table: xr.Dataset, columns, keep, path) -> Path:
    """The rows ``keep`` of ``table`` as CSV with ``columns`` ((header, variable) pairs; those
    the table has), angles in degrees, empty where not finite; atomically."""
    import csv

    from processing.base.atomic import staged
    cols = [(name, var) for name, var in columns if var in table]
    values = {}
    for name, var in cols:
        v = table[var].values[keep]
        values[name] = np.degrees(v) if var.endswith("_rad") else v
    path = Path(path)
    with staged(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([name for name, _ in cols])
        for i in range(int(np.count_nonzero(keep))):
            w.writerow([_cell(values[name][i]) for name, _ in cols])
    return path


#: detections columns a single-target row carries (where the detections table has them)
_POSITION = ("ping", "ping_index", "range_m", "azimuth_rad", "elevation_rad", "x_m", "y_m", "z_m",
             "world_x_m", "world_y_m", "world_z_m", "amplitude", "snr_db")

_UNITS = {
    "ts_uncomp_db": ("dB re 1 m2", "TS taken on axis (uncompensated)"),
    "ts_comp_db": ("dB re 1 m2", "TS compensated for the two-way beam pattern at the located position"),
    "beam_pattern_db": ("dB re axis", "two-way beam pattern at the located position (near field included "
                        "when single_target.near_field)"),
    "beam_compensation_db": ("dB", "one-way beam compensation: -beam_pattern_db / 2"),
    "echo_length_m": ("m", "width of the matched-filter envelope between its -6 dB points"),
    "echo_length": ("1", "echo length over the nominal (compressed) pulse's"),
    "phase_deviation_deg": ("arc_degree", "standard deviation of psi_AB within the echo (electrical)"),
    "angle_deviation_deg": ("arc_degree", "standard deviation of the elevation within the echo"),
    "echo_spacing": ("1", "range to the nearest other echo in the beam, in nominal pulse lengths"),
}


def single_targets(tree, settings=None) -> xr.Dataset:
    """Single-target detection by the echosounder criteria: every detection a candidate, its
    measures, TS and the rule that rejected it.

    Parameters
    ----------
    tree : xarray.DataTree, str or Path
        A dataset following the data contract (with samples; detected here unless it holds
        /Processing/Detections already).
    settings : ProcessingSettings, dict or path, optional
        The ``single_target`` section sets the criteria (:class:`processing.settings.SingleTargetSettings`);
        default: the dataset's own processing settings.

    Returns
    -------
    xarray.Dataset
        Dim ``target`` (one row per candidate): ``ping`` (row in the file), ``ping_index``,
        ``range_m``, ``azimuth_rad``, ``elevation_rad``, ``x_m``/``y_m``/``z_m`` (sonar frame),
        ``world_*_m``, ``ts_uncomp_db``, ``ts_comp_db`` (dB re 1 m²; NaN without a
        calibration, TS_comp NaN beyond the compensable beam), ``beam_pattern_db``,
        ``beam_compensation_db``, ``echo_length_m``, ``echo_length``, ``phase_deviation_deg``,
        ``angle_deviation_deg`` (NaN outside interferometric mode), ``echo_spacing`` (inf
        alone in its beam), ``rejected_by`` (str, "" for a single target: one of
        :data:`processing.backscatter.echo_criteria.RULES`) and ``single_target`` (bool).
        Attributes: the criteria as SONAR-netCDF4 2.0 ``param_*`` names, the nominal echo
        length (m) and the count of single targets.
    """
    from processing.pipeline import RecordChain
    from processing.settings import SONAR_NETCDF4_PARAMETERS
    chain = RecordChain(tree, settings)
    detected = chain.detected()
    cols = chain.target_detection(detected)
    det = detected.table
    dims = ("target",)
    data = {k: (dims, np.asarray(det[k])) for k in _POSITION if k in det}
    if "ping_index" not in data and "ping" in det:
        data["ping_index"] = (dims, chain.ping_index[np.asarray(det["ping"], int)])
    for k, v in cols.items():
        data[k] = (dims, np.asarray(v))
    out = xr.Dataset(data)
    for k, (units, long_name) in _UNITS.items():
        out[k].attrs.update(units=units, long_name=long_name)
    sts = chain.settings.single_target
    attrs = {name: (float("nan") if getattr(sts, field) is None else float(getattr(sts, field)))
             for field, (name, _) in SONAR_NETCDF4_PARAMETERS.items()}
    attrs.update(nominal_echo_length_m=float(chain.nominal_echo_length_m),
                 echo_length_level_db=float(sts.echo_length_level_db),
                 near_field_compensated=int(sts.near_field),
                 single_target_count=int(np.count_nonzero(cols["single_target"])))
    out.attrs.update(attrs)
    return out


#: CSV column -> single_targets() variable: Echoview's single-target export names where one exists
TARGET_COLUMNS = (
    ("Ping_index", "ping_index"), ("Target_range", "range_m"), ("Angle_azimuth_deg", "azimuth_rad"),
    ("Angle_elevation_deg", "elevation_rad"), ("Target_x_m", "x_m"), ("Target_y_m", "y_m"),
    ("Target_z_m", "z_m"), ("Target_world_x_m", "world_x_m"), ("Target_world_y_m", "world_y_m"),
    ("Target_world_z_m", "world_z_m"), ("TS_uncomp", "ts_uncomp_db"), ("TS_comp", "ts_comp_db"),
    ("Beam_compensation_db", "beam_compensation_db"), ("Echo_length_m", "echo_length_m"),
    ("Echo_length_normalised", "echo_length"), ("Phase_deviation_deg", "phase_deviation_deg"),
    ("Angle_deviation_deg", "angle_deviation_deg"), ("Echo_spacing", "echo_spacing"),
    ("SNR_db", "snr_db"), ("Rejected_by", "rejected_by"))


def write_targets_csv(table: xr.Dataset, path, *, accepted_only: bool = False) -> Path:
    """Write a :func:`single_targets` table as CSV (columns :data:`TARGET_COLUMNS`, angles in
    degrees, lengths in m, TS in dB re 1 m², empty where not finite — NaN, or an echo spacing of
    inf for an echo alone in its beam — and ``Rejected_by`` empty for a single target),
    atomically; ``accepted_only`` keeps the single targets only."""
    keep = (table["single_target"].values.astype(bool) if accepted_only
            else np.ones(table.sizes.get("target", 0), bool))
    return _write_rows_csv(table, TARGET_COLUMNS, keep, path)


def _cell(x):
    a = np.asarray(x)
    if a.dtype.kind in "US":
        return str(x)
    if np.issubdtype(a.dtype, np.integer):
        return int(x)
    return "" if not np.isfinite(x) else f"{float(x):.9g}"
