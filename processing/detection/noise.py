"""The noise level of sonar images: a Rayleigh fit of cell magnitudes (thesis §5.2.3).

For complex Gaussian noise of standard deviation σ per quadrature component, |I| is Rayleigh with
scale σ: mean μ = σ √(π/2), median σ √(2 ln 2). Estimators:

``ml``      σ² = Σ x² / 2n, the maximum-likelihood estimate — exact for pure noise;
``median``  σ = median(x) / √(2 ln 2) — robust to a sparse set of targets in the cells.

The fit's quality is the Kolmogorov–Smirnov statistic D against Rayleigh(σ), computed on a
decimated subset (neighbouring cells of an interpolated image are correlated, which would make a
p-value meaningless). D above the 1 % critical value of the subset flags the data as not
Rayleigh-like (targets, reverberation, clipping) and the caller warns.

A zero, negative or non-finite estimate raises :class:`NoiseEstimateError`: a noise-free image has
no noise statistics, and a threshold derived from σ = 0 would detect every sidelobe.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["NoiseEstimateError", "RayleighFit", "rayleigh_fit", "rayleigh_mean", "RAYLEIGH_MEAN_FACTOR"]

_MEDIAN_FACTOR = float(np.sqrt(2 * np.log(2)))
#: μ / σ of a Rayleigh law: √(π/2)
RAYLEIGH_MEAN_FACTOR = float(np.sqrt(np.pi / 2))


def rayleigh_mean(sigma):
    """μ = σ √(π/2): the mean of a Rayleigh law of scale σ (the thesis' noise mean μ).

    Parameters
    ----------
    sigma : float or ndarray
        Scale σ (image units), the noise standard deviation per quadrature component.

    Returns
    -------
    float or ndarray
        μ, same units and shape.
    """
    return sigma * RAYLEIGH_MEAN_FACTOR


class NoiseEstimateError(ValueError):
    """The cells carry no usable noise (zero, NaN, or too few)."""


@dataclass(frozen=True)
class RayleighFit:
    """A Rayleigh fit.

    Attributes
    ----------
    sigma : float
        Scale σ (image units) = noise standard deviation per quadrature component.
    mu : float
        Mean σ √(π/2) (the thesis' μ).
    n_cells : int
        Cells used.
    ks_statistic : float
        Kolmogorov–Smirnov D on the decimated subset.
    ks_critical : float
        1 % critical value of D for that subset (1.63 / √n).
    estimator : str
    """

    sigma: float
    mu: float
    n_cells: int
    ks_statistic: float
    ks_critical: float
    estimator: str

    @property
    def rayleigh_like(self) -> bool:
        return self.ks_statistic <= self.ks_critical

    def describe(self) -> str:
        verdict = "Rayleigh-like" if self.rayleigh_like else "NOT Rayleigh-like"
        return (f"σ = {self.sigma:.4g}, μ = {self.mu:.4g} from {self.n_cells} cells "
                f"({self.estimator}); KS D = {self.ks_statistic:.4f} vs {self.ks_critical:.4f}: {verdict}")


def rayleigh_fit(magnitudes, *, estimator: str = "median", decimate=None, max_ks: int = 20_000,
                 seed: int = 0) -> RayleighFit:
    """Fit a Rayleigh law to image magnitudes.

    Parameters
    ----------
    magnitudes : array_like
        |I| of the cells (any shape), image units.
    estimator : {"median", "ml"}
    decimate : tuple of slices, optional
        Applied to ``magnitudes`` before the KS test (e.g. every U-th range sample).
    max_ks : int
        At most this many cells enter the KS test (a seeded random subset).

    Returns
    -------
    RayleighFit

    Raises
    ------
    NoiseEstimateError
        No cells, non-finite values, or a zero estimate.
    """
    x = np.asarray(magnitudes, float)
    if x.size == 0:
        raise NoiseEstimateError("no cells to estimate the noise from")
    if not np.all(np.isfinite(x)):
        raise NoiseEstimateError("the noise cells contain NaN or inf")
    flat = x.ravel()
    if estimator == "ml":
        sigma = float(np.sqrt(np.mean(flat**2) / 2))
    elif estimator == "median":
        sigma = float(np.median(flat) / _MEDIAN_FACTOR)
    else:
        raise ValueError(f"estimator must be 'median' or 'ml', got {estimator!r}")
    if not sigma > 0:
        raise NoiseEstimateError(
            "the noise estimate is zero: these images are noise-free, so no threshold can be "
            "derived from their noise; use a fixed threshold or a fraction of the peak")
    sub = x[decimate].ravel() if decimate is not None else flat
    if sub.size > max_ks:
        sub = np.random.default_rng(seed).choice(sub, max_ks, replace=False)
    srt = np.sort(sub)
    cdf = -np.expm1(-srt**2 / (2 * sigma**2))
    n = srt.size
    d = float(max(np.max(np.arange(1, n + 1) / n - cdf), np.max(cdf - np.arange(n) / n)))
    return RayleighFit(sigma, rayleigh_mean(sigma), int(flat.size), d,
                       1.63 / np.sqrt(n), estimator)
