"""Scoring detections against the simulator's ground truth.

Detections and true targets of one ping are matched one-to-one by the Hungarian algorithm
(scipy.optimize.linear_sum_assignment) on their distance in the image plane, measured in
resolution cells (3 dB widths): Δr / δr and r·Δ(sin θ) / (r δθ), with δr and δθ the image's 3 dB widths. Pairs
farther apart than ``gate`` cells are not matched. Elevation is not used: the image cannot resolve
it, and the question "is this detection that target" is asked in the image.

Before interferometry the candidates are the detections in the counting volume's range–azimuth
span and the true targets in that span (any elevation); after, the detections located inside the
volume and the true targets inside it. A miss whose target has another true target closer than the
Rayleigh resolution (``unresolved`` cells, 1.5 by default: a Hamming-weighted aperture resolves
two equal targets only ~1.4 of its 3 dB width apart) "shares a resolution cell" — the thesis'
reason for undercounts (§6.3.1).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Score", "match", "shares_cell"]


@dataclass(frozen=True)
class Score:
    """One ping's comparison.

    Attributes
    ----------
    hits, misses, false_alarms : int
    matched_detection, matched_truth : ndarray of int
        Index pairs of the matches.
    shared_cell_misses : int
        Misses whose target has another true target within the gate.
    """

    hits: int
    misses: int
    false_alarms: int
    matched_detection: np.ndarray
    matched_truth: np.ndarray
    shared_cell_misses: int


def _cell_distance(r_d, az_d, r_t, az_t, dr, dtheta):
    rr = (r_d[:, None] - r_t[None, :]) / dr
    rbar = 0.5 * (r_d[:, None] + r_t[None, :])
    cross = rbar * (np.sin(az_d)[:, None] - np.sin(az_t)[None, :]) / (rbar * dtheta)
    return np.hypot(rr, cross)


def shares_cell(r_t, az_t, *, dr, dtheta, gate):
    """For each true target, whether another true target lies within ``gate`` cells."""
    r_t, az_t = np.asarray(r_t, float), np.asarray(az_t, float)
    if r_t.size < 2:
        return np.zeros(r_t.size, bool)
    d = _cell_distance(r_t, az_t, r_t, az_t, dr, dtheta)
    np.fill_diagonal(d, np.inf)
    return (d <= gate).any(axis=1)


def match(r_d, az_d, r_t, az_t, *, dr: float, dtheta: float, gate: float = 1.0,
          unresolved: float = 1.5) -> Score:
    """Match detections (range m, azimuth rad) to true targets of one ping.

    Parameters
    ----------
    r_d, az_d : array_like, shape (n_d,)
    r_t, az_t : array_like, shape (n_t,)
    dr : float
        Range resolution (m).
    dtheta : float
        Azimuth resolution (rad).
    gate : float
        Largest distance, in resolution cells, of a match.
    unresolved : float
        A missed target with another true target closer than this (cells) shares a cell.
    """
    r_d, az_d, r_t, az_t = (np.asarray(v, float).reshape(-1) for v in (r_d, az_d, r_t, az_t))
    nd, nt = r_d.size, r_t.size
    if nd == 0 or nt == 0:
        shared = int(shares_cell(r_t, az_t, dr=dr, dtheta=dtheta, gate=unresolved).sum())
        return Score(0, nt, nd, np.zeros(0, int), np.zeros(0, int), shared if nd == 0 else 0)
    d = _cell_distance(r_d, az_d, r_t, az_t, dr, dtheta)
    cost = np.where(d <= gate, d, 1e6)
    from scipy.optimize import linear_sum_assignment  # here: a 0.3 s import
    rows, cols = linear_sum_assignment(cost)
    ok = cost[rows, cols] < 1e6
    rows, cols = rows[ok], cols[ok]
    missed = np.setdiff1d(np.arange(nt), cols)
    shared = shares_cell(r_t, az_t, dr=dr, dtheta=dtheta, gate=unresolved)
    return Score(int(ok.sum()), int(nt - ok.sum()), int(nd - ok.sum()), rows, cols,
                 int(shared[missed].sum()))
