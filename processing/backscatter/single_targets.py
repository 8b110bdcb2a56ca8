"""Single targets: which detections are one fish's own echo, with its target strength.

Echosounder practice (Echoview's single-target detection, Sonar5's) keeps a detection as a
single target when it is not another echo's sidelobe and its beam-compensated TS is above a
threshold. Here a detection of a dataset is a single target when

* no stronger detection of its ping lies in its resolution cell, or within 2.5 range cells and
  ``sidelobe_db`` stronger (:func:`single_targets`: range and azimuth sidelobes, grating ghosts);
* its compensated TS is at least ``min_ts_db``, or NaN (beyond the compensable beam, where no TS
  can be given but the echo is real): far range sidelobes of the Hamming range window (≈ −80 dB)
  and multipath echoes fall below it.

:meth:`processing.pipeline.RecordChain.single_targets` gives every detection its TS (uncompensated
and compensated for the two-way beam pattern at its located angles,
processing/backscatter/target_strength.py) and the verdict; :mod:`processing.backscatter.target_table`
makes it a table of a dataset and exports it with columns close to Echoview's single-target export.
"""
from __future__ import annotations

import numpy as np

__all__ = ["single_targets"]


def single_targets(ping_rows, range_m, azimuth_rad, amplitude, *, range_resolution_m: float,
                   azimuth_resolution_rad: float, sidelobe_db: float, same_cell: bool = True):
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
    same_cell : bool
        Also drop the weaker of two detections in one resolution cell (the tracker's rule: a
        second peak of the same echo). False keeps only the sidelobe test, for the echosounder
        criteria (:mod:`processing.backscatter.echo_criteria`), which judge such pairs by their
        echoes, and for the tracker with its resolution gate, which keeps such a peak from
        starting a track but lets a fish side by side with a stronger one be followed
        (processing/tracking/filters.py).

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
        cell = ((np.abs(az[k][:, None] - az[k][None, :]) <= 1.5 * azimuth_resolution_rad)
                & (np.abs(r[k][:, None] - r[k][None, :]) <= range_resolution_m))
        far_above = a[k][:, None] > ratio * a[k][None, :]
        if not same_cell:
            cell = np.zeros_like(cell)
        keep[k] = ~np.any(stronger & near & (cell | far_above), axis=0)
    return keep
