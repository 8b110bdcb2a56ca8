"""The track-splitting part of the tracker: a track that holds two fish crossing the fan one
behind the other is cut where the second one enters.

A multibeam's fan is thin in elevation (0.86° for ABACUS: 0.28 m at 19 m) and the
interferometer places each echo across it, so a fish swimming through the fan moves through it
monotonically: its detections' coordinate through the fan, u = n·(z − p) (n the sonar's
elevation axis in the world frame, p the sonar's position; u = 0 on the fan's centre plane),
follows a line u = a + b t at the fish's own speed b through the fan. A second fish entering
behind the first (one behind the other at one range and azimuth, so that the gate cannot tell
their echoes apart) appears at the entry face again: against the track's own motion u steps
back, and from there follows its own line. Along the fan (a fish whose elevation only scatters
about a constant, or drifts slowly) a step is no evidence of a second fish.

The test (:class:`FanCrossingSplit`), on a finished track's detections, each weighted by its
own variance through the fan nᵀRn (:func:`processing.tracking.filters.measurement_covariance`):

* one fish: the weighted least-squares line; two fish: a line each, before and after a break
  (Quandt 1958's two-phase regression), at the break that fits best;
* the likelihood ratio Δχ² = χ²_one − χ²_two, divided by the two lines' residual variance per
  degree of freedom where that exceeds 1 (an echo merged with a neighbour's is placed worse than
  its own SNR says: the fit's own scatter then sets the scale, as in an F test), must exceed the
  chi-square quantile of ``probability`` with 2 degrees of freedom (an intercept and a slope
  more);
* each fish must move through the fan, the same way: both slopes of one sign and each apart
  from 0 beyond the 1-degree-of-freedom quantile of ``probability``, each line's errors scaled
  by its own residual variance where that exceeds 1;
* at the break the second line lies behind the first, against that motion, by as much, and the
  two straddle the fan's centre plane — the first past it, the second before it: of two fish
  that give one echo, the one nearer the centre plane is the stronger in the transmitter's
  elevation pattern, so the second takes the echo over as it comes nearer than the first;
* the track dwells in the fan (the time from its first to its last detection with
  |u| ≤ w/2, w the fan's thickness at the detection's range) longer than one fish crosses it at
  the slower of the two speeds, w/|b| — what a single fish could not do;
* each part holds ``min_hits`` detections (a confirmable track).

A track cut in two is tested again in each part (binary segmentation: Scott & Knott 1974;
Killick & Eckley 2014 review change-point detection), so a track holding three fish in a row is
cut twice.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FanCrossingSplit", "NoSplit", "splitter"]


def _wls(X, u, w):
    """Weighted least squares: coefficients (p,), their covariance (p, p) and χ² of the fit."""
    A = X.T @ (w[:, None] * X)
    try:
        C = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return None, None, np.inf
    beta = C @ (X.T @ (w * u))
    r = u - X @ beta
    return beta, C, float(np.sum(w * r * r))


@dataclass(frozen=True)
class NoSplit:
    """No track splitting: every finished track is kept whole."""

    name = "none"

    def breaks(self, time_s, through_fan_m, variance_m2, fan_width_m):
        """No break: an empty list."""
        return []


@dataclass(frozen=True)
class FanCrossingSplit:
    """Cut a track where it steps back through the fan against its own motion.

    Attributes
    ----------
    probability : float
        The probability whose chi-square quantiles the two lines' likelihood ratio against one
        (2 degrees of freedom), each line's slope and the step back at the break (1 degree of
        freedom each) must exceed.
    min_hits : int
        Detections each part must hold.
    """

    probability: float = 0.999
    min_hits: int = 3
    name = "fan_crossing"

    def __post_init__(self):
        if not 0.5 < self.probability < 1:
            raise ValueError(f"split probability must lie in (0.5, 1), got {self.probability}")
        if self.min_hits < 2:
            raise ValueError(f"split min_hits must be at least 2, got {self.min_hits}")

    @property
    def threshold(self) -> float:
        """The chi-square quantile (1 degree of freedom) of ``probability``."""
        from scipy.stats import chi2
        return float(chi2.ppf(self.probability, 1))

    @property
    def threshold2(self) -> float:
        """The chi-square quantile (2 degrees of freedom) of ``probability``: the two lines'
        likelihood ratio against one (one more intercept, one more slope)."""
        from scipy.stats import chi2
        return float(chi2.ppf(self.probability, 2))

    def breaks(self, time_s, through_fan_m, variance_m2, fan_width_m):
        """Where a track's detections are cut into fish that crossed the fan one after another.

        Parameters
        ----------
        time_s : array_like, shape (k,)
            Time of each detection of the track (s), ascending.
        through_fan_m : array_like, shape (k,)
            Each detection's coordinate through the fan, u = n·(z − p) (m; 0 on the fan's
            centre plane).
        variance_m2 : array_like, shape (k,)
            Its variance nᵀRn (m²).
        fan_width_m : array_like, shape (k,)
            The fan's thickness at each detection's range (m): range × the transmitter's
            elevation beamwidth.

        Returns
        -------
        list of int
            Ascending indices i (0 < i < k): a new fish starts at detection i.
        """
        t = np.asarray(time_s, float)
        u = np.asarray(through_fan_m, float)
        v = np.asarray(variance_m2, float)
        width = np.broadcast_to(np.asarray(fan_width_m, float), t.shape)
        ok = np.isfinite(t) & np.isfinite(u) & np.isfinite(v) & (v > 0) & np.isfinite(width)
        if not ok.all():
            idx = np.flatnonzero(ok)
            return [int(idx[i]) for i in self.breaks(t[ok], u[ok], v[ok], width[ok])]
        return self._segment(t, u, 1.0 / v, width, 0, self.threshold)

    def _segment(self, t, u, w, width, offset, thr):
        i = self._best_break(t, u, w, width, thr)
        if i is None:
            return []
        return (self._segment(t[:i], u[:i], w[:i], width[:i], offset, thr) + [offset + i]
                + self._segment(t[i:], u[i:], w[i:], width[i:], offset + i, thr))

    def _best_break(self, t, u, w, width, thr):
        k = len(t)
        if k < 2 * self.min_hits:
            return None
        _, _, chi0 = _wls(np.stack([np.ones(k), t - np.average(t, weights=w)], -1), u, w)
        best, best_stat = None, self.threshold2
        for i in range(self.min_hits, k - self.min_hits + 1):
            tau = 0.5 * (t[i - 1] + t[i])
            # each fish its own line through the fan, both referred to the break's time
            first = np.arange(k) < i
            X = np.zeros((k, 4))
            X[first, 0], X[first, 1] = 1.0, t[first] - tau
            X[~first, 2], X[~first, 3] = 1.0, t[~first] - tau
            beta, C, chi1 = _wls(X, u, w)
            if beta is None:
                continue
            scale = max(1.0, chi1 / max(k - 4, 1))
            # each line's own scatter scales its own errors (a part of merged echoes is placed
            # worse than a part of clean ones; the two lines' errors are independent)
            r2 = w * (u - X @ beta) ** 2
            s1 = max(1.0, r2[first].sum() / max(i - 2, 1))
            s2 = max(1.0, r2[~first].sum() / max(k - i - 2, 1))
            b1, b2, jump = beta[1], beta[3], beta[2] - beta[0]
            var_jump = C[0, 0] * s1 + C[2, 2] * s2
            # two fish crossing one behind the other: each moves through the fan, the same way
            # (as much evidence of motion as the test asks), and at the break the second is
            # behind the first, against that motion
            if (b1 * b2 <= 0 or min(b1 * b1 / (C[1, 1] * s1), b2 * b2 / (C[3, 3] * s2)) < thr
                    or jump * b1 >= 0 or jump * jump / var_jump < thr):
                continue
            # the hand-over of one merged echo: the fish nearer the fan's centre plane (u = 0)
            # is the stronger in the transmitter's elevation pattern, so the second takes the
            # echo as it comes nearer than the first — the first past the centre plane, the
            # second before it
            if beta[0] * b1 <= 0 or beta[2] * b1 >= 0:
                continue
            # and the track stays in the fan longer than one fish moving through it as fast
            # as the slower of the two could: its dwell is evidence of a second fish
            inside = np.abs(u) <= 0.5 * width
            if not inside.any() or np.ptp(t[inside]) * min(abs(b1), abs(b2)) <= np.mean(width[inside]):
                continue
            stat = (chi0 - chi1) / scale
            if stat > best_stat:
                best, best_stat = i, stat
        return best


def splitter(name: str, *, probability: float = 0.999, min_hits: int = 3):
    """The track-splitting part named by the setting ``track.split``: "none" or "fan_crossing".

    ``probability`` is ``track.split_probability``; ``min_hits`` the detections each part must
    hold (the tracker passes ``track.confirm_hits``), raised to 2: each part is a line through
    the fan, which one detection does not make (``confirm_hits: 1`` is an accepted setting)."""
    if name == "none":
        return NoSplit()
    if name == "fan_crossing":
        return FanCrossingSplit(probability, max(2, int(min_hits)))
    raise ValueError(f"tracking split must be 'none' or 'fan_crossing', got {name!r}")
