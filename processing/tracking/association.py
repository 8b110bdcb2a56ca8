"""The gate-and-assign part of the tracker: which detection of a ping belongs to which track.

A detection j is in track i's gate when the Mahalanobis distance d² = νᵀ S⁻¹ ν of its innovation
ν (against the track's predicted position, S its innovation covariance) is below the chi-square
quantile of the gate probability (3 degrees of freedom). Two ways to use the gated pairs, chosen
by the setting ``track.association``:

* ``"gnn"`` — global nearest neighbour: one detection per track and one track per detection,
  minimising Σ (d² + ln|S|) (the negative log-likelihood, so a tight track does not lose its
  detection to a loose one) by the Hungarian algorithm (:func:`scipy.optimize.linear_sum_assignment`);
* ``"jpda"`` — joint probabilistic data association, in the parametric approximation of
  Fitzgerald (1985) ("cheap JPDA"): a detection shared by several gates is shared among their
  tracks by weight β_ij = G_ij / (T_i + D_j − G_ij + B), G_ij the Gaussian likelihood, T_i and
  D_j its row and column sums, B the clutter density; each track updates with the weighted
  innovations (:meth:`processing.tracking.motion.ConstantVelocityKalman.update_mixture`) when
  more than one detection falls in its gate. Which detection a track holds (its hits, and the
  detections left to start new tracks) is still the global nearest neighbour's one-to-one
  assignment, so two tracks never both own one echo; only the state update is shared.
"""
from __future__ import annotations

import numpy as np

__all__ = ["gate_threshold", "gated_costs", "global_nearest_neighbour", "jpda_weights"]

# chi-square quantiles with 3 degrees of freedom (scipy.stats.chi2.ppf(p, 3)), tabulated to keep
# scipy.stats out of the import path; other probabilities are computed on demand
_CHI2_3 = {0.9: 6.251388631170325, 0.95: 7.814727903251178, 0.99: 11.344866730144373,
           0.999: 16.26623619623813}


def gate_threshold(probability: float) -> float:
    """Chi-square quantile (3 degrees of freedom) of ``probability``: the gate on d²."""
    p = float(probability)
    if p in _CHI2_3:
        return _CHI2_3[p]
    from scipy.stats import chi2
    return float(chi2.ppf(p, 3))


def gated_costs(predicted_m, innovation_cov_m2, detections_m, gate: float):
    """Mahalanobis distances and negative log-likelihoods of every track–detection pair.

    Parameters
    ----------
    predicted_m : ndarray, shape (t, 3)
        Tracks' predicted positions (m).
    innovation_cov_m2 : ndarray, shape (t, d, 3, 3)
        Innovation covariance of each pair (m²).
    detections_m : ndarray, shape (d, 3)
        The ping's detections (m).
    gate : float
        Threshold on d² (:func:`gate_threshold`).

    Returns
    -------
    d2 : ndarray, shape (t, d)
        Mahalanobis distance squared (inf outside the gate).
    cost : ndarray, shape (t, d)
        d² + ln|S| (inf outside the gate): the negative log-likelihood up to a constant.
    """
    t, d = len(predicted_m), len(detections_m)
    if t == 0 or d == 0:
        return np.full((t, d), np.inf), np.full((t, d), np.inf)
    nu = np.asarray(detections_m, float)[None, :, :] - np.asarray(predicted_m, float)[:, None, :]
    S = np.asarray(innovation_cov_m2, float)
    d2 = np.einsum("tdi,tdij,tdj->td", nu, np.linalg.inv(S), nu)
    _, logdet = np.linalg.slogdet(S)
    inside = d2 <= gate
    return np.where(inside, d2, np.inf), np.where(inside, d2 + logdet, np.inf)


def global_nearest_neighbour(cost):
    """One-to-one assignment of least total cost among the finite entries of ``cost`` (t, d).

    Returns
    -------
    rows, cols : ndarray of int
        Assigned (track, detection) pairs; a track or detection whose every entry is inf
        stays unassigned.
    """
    cost = np.asarray(cost, float)
    if cost.size == 0:
        return np.array([], int), np.array([], int)
    from scipy.optimize import linear_sum_assignment
    big = 1e12
    c = np.where(np.isfinite(cost), cost, big)
    rows, cols = linear_sum_assignment(c)
    keep = c[rows, cols] < big
    return rows[keep], cols[keep]


def jpda_weights(cost, *, detection_probability: float = 0.9, clutter: float = 1e-3):
    """Association probabilities of the parametric ("cheap") JPDA (Fitzgerald 1985).

    Parameters
    ----------
    cost : ndarray, shape (t, d)
        d² + ln|S| of each pair, inf outside the gate (:func:`gated_costs`).
    detection_probability : float
        P_D of a track's fish in one ping.
    clutter : float
        B, the likelihood of a detection being none of these tracks' (same units as the
        Gaussian likelihood exp(−cost/2) / (2π)^{3/2}: m⁻³).

    Returns
    -------
    ndarray, shape (t, d)
        β_ij; each row sums to at most 1 (the rest: the track's fish was missed).
    """
    cost = np.asarray(cost, float)
    finite = np.isfinite(cost)
    if not finite.any():
        return np.zeros(cost.shape)
    # likelihoods scaled by exp(c_min/2) (2π)^{3/2} to stay finite; B scaled alike
    c_min = cost[finite].min()
    G = np.where(finite, detection_probability * np.exp(-0.5 * (np.where(finite, cost, c_min) - c_min)), 0.0)
    B = clutter * np.exp(0.5 * c_min) * (2 * np.pi) ** 1.5
    T = G.sum(axis=1, keepdims=True)
    D = G.sum(axis=0, keepdims=True)
    return np.where(G > 0, G / (T + D - G + B), 0.0)
