"""Detection thresholds (thesis §5.2): from a false-alarm probability, fixed, relative, or CFAR.

False-alarm probability per cell from one per image of N tested cells:

``correct``  "at most probability α of any false alarm in the image":
             P_cell = 1 − (1 − α)^(1/N) ≈ α/N, and for Rayleigh noise of scale σ
             T = σ √(−2 ln P_cell)  (from P_cell = exp(−T²/2σ²), eq. 5.8).
``thesis``   eq. 5.4 and 5.9 as printed: P_cell = 1 − α^(1/N) and T = √(−2 μ² (π/2) ln P_cell)
             with μ the Rayleigh mean — two slips (../shared/reference/ABACUS.md) that together
             give 9.05e-4 and T ≈ 656 for μ = 139.8, α = 1e-7, N = 17802.

CFAR (for noise that varies with range or ping): the square-law |I|² of Rayleigh noise is
exponential, so with N training cells

- cell averaging: T² = a · mean(training), a = N (P^(−1/N) − 1);
- ordered statistic (k-th smallest of N): T² = a · x_(k), a solving
  P = Π_{i=0}^{k−1} (N − i)/(N − i + a)   (Rohling 1983).
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import correlate, rank_filter

from processing.detection.noise import rayleigh_mean

__all__ = ["CONVENTIONS", "cell_pfa", "rayleigh_threshold", "ca_cfar_factor", "os_cfar_factor",
           "cfar_threshold"]

CONVENTIONS = ("correct", "thesis")


def cell_pfa(pfa_image: float, n_cells: int, *, convention: str = "correct") -> float:
    """Per-cell false-alarm probability for ``n_cells`` independent tests."""
    if not 0 < pfa_image < 1:
        raise ValueError(f"pfa_image must lie in (0, 1), got {pfa_image}")
    if n_cells < 1:
        raise ValueError(f"n_cells must be >= 1, got {n_cells}")
    if convention == "correct":
        return float(-np.expm1(np.log1p(-pfa_image) / n_cells))
    if convention == "thesis":
        return float(-np.expm1(np.log(pfa_image) / n_cells))
    raise ValueError(f"convention must be one of {CONVENTIONS}, got {convention!r}")


def rayleigh_threshold(sigma: float, pfa_cell: float, *, convention: str = "correct") -> float:
    """Threshold on |I| for Rayleigh noise of scale σ (the thesis' μ = σ√(π/2))."""
    if not sigma > 0 or not np.isfinite(sigma):
        raise ValueError(f"the noise scale must be a positive number, got {sigma}")
    if not 0 < pfa_cell < 1:
        raise ValueError(f"pfa_cell must lie in (0, 1), got {pfa_cell}")
    if convention == "correct":
        return float(sigma * np.sqrt(-2.0 * np.log(pfa_cell)))
    if convention == "thesis":
        mu = rayleigh_mean(sigma)
        return float(np.sqrt(-2.0 * mu**2 * (np.pi / 2) * np.log(pfa_cell)))
    raise ValueError(f"convention must be one of {CONVENTIONS}, got {convention!r}")


def ca_cfar_factor(n_training: int, pfa: float) -> float:
    """Scale a on the training mean of |I|² for CA-CFAR under exponential (Rayleigh) noise."""
    return float(n_training * (pfa ** (-1.0 / n_training) - 1.0))


def os_cfar_factor(n_training: int, k: int, pfa: float) -> float:
    """Scale a on the k-th smallest training |I|² (1-based) for OS-CFAR."""
    if not 1 <= k <= n_training:
        raise ValueError(f"k must be in 1..{n_training}, got {k}")
    i = np.arange(k)

    def f(a):
        return np.sum(np.log((n_training - i) / (n_training - i + a))) - np.log(pfa)

    hi = 1.0
    while f(hi) > 0:
        hi *= 2
    from scipy.optimize import brentq  # here: scipy.optimize costs 0.3 s to import
    return float(brentq(f, 0.0, hi, xtol=1e-12))


def _window(guard, training):
    gr, gb = guard
    tr, tb = training
    shape = (2 * (gr + tr) + 1, 2 * (gb + tb) + 1)
    w = np.ones(shape, bool)
    c0, c1 = gr + tr, gb + tb
    w[c0 - gr:c0 + gr + 1, c1 - gb:c1 + gb + 1] = False
    return w


def cfar_threshold(mag, *, pfa: float, kind: str = "ca", guard=(8, 1), training=(24, 3),
                   rank: float = 0.75):
    """Per-cell CFAR threshold on |I| (same shape as ``mag``, image units).

    The training window is the rectangle of (guard + training) cells each side minus the guard
    rectangle; at the image edges the image is mirrored. Cells whose training cells are all zero
    (no noise to measure) get an infinite threshold.

    Returns
    -------
    threshold : ndarray, shape of mag
    n_training : int
    factor : float
    """
    p = np.asarray(mag, float) ** 2
    w = _window(guard, training)
    n = int(w.sum())
    if kind == "ca":
        a = ca_cfar_factor(n, pfa)
        level = correlate(p, w.astype(float) / n, mode="mirror")
    elif kind == "os":
        k = max(1, min(n, int(round(rank * n))))
        a = os_cfar_factor(n, k, pfa)
        level = rank_filter(p, k - 1, footprint=w, mode="mirror")
    else:
        raise ValueError(f"CFAR kind must be 'ca' or 'os', got {kind!r}")
    with np.errstate(divide="ignore"):
        thr = np.where(level > 0, np.sqrt(a * np.maximum(level, 0)), np.inf)
    return thr, n, a
