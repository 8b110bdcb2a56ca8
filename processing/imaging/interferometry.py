"""Phase interferometry between the images of subarrays A and B (thesis §4.7).

The interferogram I_AB = I_A · I_B* (eq. 4.60) has the wrapped phase ψ_AB = ψ_A − ψ_B (4.61).
For a baseline b = c_B − c_A between the subarrays' phase centres and a target in direction û,
ψ_AB = −(2π/λ) b·û (4.56–4.58). With b along +y this is the thesis' ψ = −(2π/λ) b sin φ and

    φ = arcsin(−ψ λ / (2π b))                                                   (4.59)

ABACUS' subarray B is also shifted along x (docs/arrays.md), so b·û = b_x cos φ sin θ + b_y sin φ
+ b_z cos φ cos θ; with θ the cell's beam angle this is A cos φ + B sin φ = s, solved in closed
form as φ = arcsin(s/R) − atan2(A, B), R = √(A² + B²). The arcsin argument is clipped to [−1, 1]
and clipped cells are flagged: never NaN.
"""
from __future__ import annotations

import numpy as np

__all__ = ["interferogram", "elevation_from_phase", "phase_from_elevation"]


def interferogram(image_a, image_b):
    """I_A · conj(I_B), and its wrapped phase ψ_AB in (−π, π].

    Parameters
    ----------
    image_a, image_b : ndarray, complex, same shape (..., n_range, n_beams)

    Returns
    -------
    product : ndarray, complex128, same shape
    psi_rad : ndarray, float64, same shape
        0 where either image is exactly 0 (no phase to measure).
    """
    prod = np.asarray(image_a) * np.conj(np.asarray(image_b))
    return prod, np.angle(prod)


def elevation_from_phase(psi_rad, beam_angle_rad, baseline_m, wavelength_m):
    """Elevation φ (rad) of each cell from its interferometric phase.

    Parameters
    ----------
    psi_rad : array_like, shape (..., n_beams)
        Wrapped ψ_AB.
    beam_angle_rad : array_like, shape (n_beams,)
        Azimuth θ of each beam.
    baseline_m : array_like, shape (3,)
        b = c_B − c_A (m), sonar frame.
    wavelength_m : float

    Returns
    -------
    phi_rad : ndarray, same shape as psi
    clipped : ndarray of bool, same shape
        Where |s/R| exceeded 1 (no elevation explains the phase; φ is ±90° − γ there).
    """
    b = np.asarray(baseline_m, float)
    th = np.asarray(beam_angle_rad, float)
    a = b[0] * np.sin(th) + b[2] * np.cos(th)
    bb = b[1]
    r = np.hypot(a, bb)
    if np.any(r == 0):
        raise ValueError("the baseline has no component that elevation changes (b_y = 0)")
    s = -np.asarray(psi_rad, float) * wavelength_m / (2 * np.pi)
    arg = s / r
    clipped = np.abs(arg) > 1.0
    phi = np.arcsin(np.clip(arg, -1.0, 1.0)) - np.arctan2(a, bb)
    return phi, clipped


def phase_from_elevation(phi_rad, theta_rad, baseline_m, wavelength_m):
    """ψ_AB (wrapped) of a target at (θ, φ): the forward model, for tests and plots."""
    b = np.asarray(baseline_m, float)
    th, ph = np.asarray(theta_rad, float), np.asarray(phi_rad, float)
    bu = b[0] * np.cos(ph) * np.sin(th) + b[1] * np.sin(ph) + b[2] * np.cos(ph) * np.cos(th)
    return np.angle(np.exp(-2j * np.pi * bu / wavelength_m))
