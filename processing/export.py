"""A dataset and its products as one SONAR-netCDF4 2.0 file (``processing.write_sonar_netcdf2``).

:mod:`processing.base.sonar_netcdf2` writes the file from explicit inputs; this module gathers
them from a dataset: the single targets of the echosounder criteria
(:func:`processing.single_targets`: its accepted rows, with their track ids where the dataset was
tracked, and the criteria as the group's ``param_*`` values) and the MVBS grid of
:func:`processing.sv`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["write_sonar_netcdf2", "single_target_columns"]


def single_target_columns(tree, settings=None) -> tuple[dict, dict]:
    """The single targets of a dataset as the 2.0 writer takes them.

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset (detected here if it holds no /Processing/Detections).
    settings : ProcessingSettings, dict or path, optional

    Returns
    -------
    columns : dict of str to ndarray, shape (n_targets,)
        ``ping`` (row of the file), ``range_m``, ``azimuth_deg``, ``elevation_deg``, ``x_m``,
        ``y_m``, ``z_m``, ``ts_uncomp_db``, ``ts_comp_db`` (dB re 1 m²), ``track_id`` (−1 where
        not tracked).
    parameters : dict
        The detection's parameters by :data:`processing.base.sonar_netcdf2.TARGET_PARAMETERS`'
        keys (those the detector has).
    """
    from processing.backscatter.target_table import single_targets
    from processing.base.contract import TRACKS_GROUP
    from processing.base.dataset import group_of
    from processing.base.sonar_netcdf2 import TARGET_PARAMETERS
    table = single_targets(tree, settings)
    keep = np.asarray(table["single_target"].values, bool)
    det_rows = np.flatnonzero(keep)
    cols = {"ping": table["ping"].values[keep].astype(int),
            "range_m": table["range_m"].values[keep],
            "azimuth_deg": np.degrees(table["azimuth_rad"].values[keep]),
            "elevation_deg": np.degrees(table["elevation_rad"].values[keep]),
            "ts_uncomp_db": table["ts_uncomp_db"].values[keep],
            "ts_comp_db": table["ts_comp_db"].values[keep]}
    for a in "xyz":
        if f"{a}_m" in table:
            cols[f"{a}_m"] = table[f"{a}_m"].values[keep]
    track = np.full(det_rows.size, -1)
    tracks = group_of(tree, TRACKS_GROUP)
    if tracks is not None and "point_detection" in tracks.variables:
        det = np.asarray(tracks["point_detection"].values, int)
        owner = np.asarray(tracks["point_track"].values, int)
        ids = np.asarray(tracks["track_id"].values, int) if "track_id" in tracks.variables else None
        of_detection = {int(d): int(ids[t] if ids is not None else t) for d, t in zip(det, owner) if d >= 0}
        track = np.array([of_detection.get(int(r), -1) for r in det_rows], int)
    cols["track_id"] = track
    # the criteria the table was made with, by their SONAR-netCDF4 2.0 names (its attributes)
    params = {key: float(table.attrs[name]) for name, key in TARGET_PARAMETERS.items() if name in table.attrs}
    return cols, params


def write_sonar_netcdf2(tree, path, settings=None, *, single_targets="auto", gridded="auto",
                        range_bin_m: float = 0.5, ping_bin: int = 10, command: str = "") -> Path:
    """Write a dataset as SONAR-netCDF4 2.0, with its single targets and gridded Sv.

    Parameters
    ----------
    tree : xarray.DataTree or str or Path
        A dataset (or its file) of the 1.0 contract.
    path : str or Path
        The ``.nc`` file to write (atomically).
    settings : ProcessingSettings, dict or path, optional
        Processing settings (the single targets' and the Sv grid's).
    single_targets : {"auto", True, False}
        The /Sonar/Beam_group1/SingleTarget group: "auto" where the dataset holds detections
        (/Processing/Detections), True always (detected here if need be), False never.
    gridded : {"auto", True, False}
        The /Sonar/Grid_group1 group of MVBS: "auto" where the dataset holds /Processing/Sv,
        True always (:func:`processing.sv` with ``range_bin_m``, ``ping_bin``), False never.
    range_bin_m, ping_bin :
        The MVBS grid made when ``gridded=True`` and the dataset has none.
    command : str
        The command line, for /Provenance's history.

    Returns
    -------
    Path
    """
    from processing.backscatter.sv import backscatter
    from processing.base.contract import DETECTIONS_GROUP, SV_GROUP
    from processing.base.dataset import as_tree, group_of
    from processing.base.sonar_netcdf2 import write_sonar_netcdf2 as write
    tree = as_tree(tree)
    targets = params = grid = None
    if single_targets is True or (single_targets == "auto" and group_of(tree, DETECTIONS_GROUP) is not None):
        targets, params = single_target_columns(tree, settings)
    if gridded is True or (gridded == "auto" and group_of(tree, SV_GROUP) is not None):
        if group_of(tree, SV_GROUP) is None:
            tree = backscatter(tree, settings, range_bin_m=range_bin_m, ping_bin=ping_bin)
        grid = tree[SV_GROUP].to_dataset(inherit=False)
    return write(tree, path, targets=targets, target_parameters=params, grid=grid, command=command)
