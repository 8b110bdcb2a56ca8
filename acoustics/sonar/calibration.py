"""The sonar's absolute calibration, as echo integration needs it (written to /Sonar).

An image of the simulator is calibrated so that a point target of backscatter amplitude ρ
(σ_bs = ρ²) at range r, azimuth θ and elevation φ peaks at

    |I| = G ρ |E_t(θ, φ)| |D(θ, φ)| 10^(−α r / 10) / r²,      G = k S,

with k the ADC scale (counts per unit pressure), S = Σ w the transmitter's on-axis source level
(a unit-driven element gives unit pressure at 1 m), E_t the transmitter's normalised response, D
the receiver element's directivity and α the absorption (dB/m). For fish spread through the beam
with volume backscattering coefficient s_v, the mean intensity of the image cell (r, θ_b) is then

    E|I|² = s_v G² 10^(−α r / 5) / r² · L_r · Ψ(θ_b),
    Ψ(θ_b) = ∫ Φ(θ) |B_b(θ)|² dθ,    Φ(θ) = ∫ |E_t(θ, φ)|² |D(θ, φ)|² cos φ dφ,

where L_r is the range integral of the compressed pulse's intensity and B_b the receive beam;
both belong to the processing (:mod:`processing.backscatter.echo_integration`), which never sees the arrays.
What belongs to the sonar — G and the two-way elevation width Φ(θ) — is computed here once per
run and recorded; a recorded dataset supplies the same two numbers from its calibration.
"""
from __future__ import annotations

import numpy as np

from acoustics.sonar.arrays import ElementArray
from acoustics.sonar.cache import array_key, per_geometry
from acoustics.sonar.directivity import array_pattern, element_directivity, unit_vector

__all__ = ["calibration_gain_counts", "two_way_elevation_width", "sonar_calibration"]


def sonar_calibration(transmitter: ElementArray, receiver: ElementArray, *, wavenumber_rad_m: float,
                      scale_counts: float):
    """The sonar's part of the calibration of a run, cached per geometry.

    Parameters
    ----------
    transmitter, receiver : ElementArray
        The ganged transmitter and the recorded receiver elements (sonar frame).
    wavenumber_rad_m : float
        k at the carrier (rad/m).
    scale_counts : float
        k_ADC: counts per unit pressure.

    Returns
    -------
    gain_counts_m : float
        G = k S (ADC counts x m).
    azimuth_rad : ndarray, shape (A,)
        Azimuth grid of Φ.
    width_rad : ndarray, shape (A,)
        Φ(θ), the two-way elevation width (rad).
    """
    key = (array_key(transmitter), array_key(receiver), float(wavenumber_rad_m))
    az, width = per_geometry("elevation_width", key, lambda: two_way_elevation_width(
        transmitter, receiver, wavenumber_rad_m=wavenumber_rad_m))
    return calibration_gain_counts(transmitter, scale_counts), az, width


def calibration_gain_counts(transmitter: ElementArray, scale_counts: float) -> float:
    """G = k S (ADC counts x m): the image peak of a ρ = 1 m target at 1 m on axis."""
    return float(scale_counts * transmitter.weight.sum())


def two_way_elevation_width(transmitter: ElementArray, receiver: ElementArray, *,
                            wavenumber_rad_m: float, azimuth_rad=None, elevation_rad=None):
    """Φ(θ) = ∫ |E_t(θ, φ)|² |D(θ, φ)|² cos φ dφ, the transmit x receive-element pattern
    integrated over elevation, on an azimuth grid (far field).

    Parameters
    ----------
    transmitter : ElementArray
        Ganged transmitter (sonar frame).
    receiver : ElementArray
        Receiver elements; their mean |D|² is used (identical elements in ABACUS).
    wavenumber_rad_m : float
    azimuth_rad : array_like, shape (A,), optional
        Default −30° to 30° every 0.25°: Φ is smooth in azimuth (the transmitter is 10° wide),
        and the transmitter is 40 dB down beyond ±30°.
    elevation_rad : array_like, shape (E,), optional
        Integration grid; default every 0.005° within ±1.5° (the 0.86° main lobe) and every
        0.05° out to ±12° (sidelobes; beyond, < 0.1 % of the energy).

    Returns
    -------
    azimuth_rad : ndarray, shape (A,)
    width_rad : ndarray, shape (A,)
        Φ (rad).
    """
    az = (np.radians(np.arange(-30.0, 30.0 + 1e-9, 0.25)) if azimuth_rad is None
          else np.asarray(azimuth_rad, float))
    if elevation_rad is None:
        el = np.radians(np.unique(np.round(np.concatenate(
            [np.arange(-1.5, 1.5 + 1e-9, 0.005), np.arange(-12.0, 12.0 + 1e-9, 0.05)]), 9)))
    else:
        el = np.asarray(elevation_rad, float)
    far = 1.0e4  # m: far field of a 0.25 m aperture at 420 kHz (L²/λ ≈ 17 m)
    width = np.empty(az.size)
    rows = max(1, 200_000 // el.size)      # azimuths per batch: bounded memory, few calls
    for i in range(0, az.size, rows):
        a = az[i:i + rows]
        A, E = np.meshgrid(a, el, indexing="ij")
        e_t = np.abs(array_pattern(transmitter, A, E, wavenumber_rad_m=wavenumber_rad_m))
        p = far * unit_vector(A, E).reshape(-1, 3)
        d2 = np.mean(np.abs(element_directivity(receiver, p, wavenumber_rad_m=wavenumber_rad_m)) ** 2,
                     axis=1).reshape(A.shape)
        width[i:i + rows] = np.trapezoid(e_t ** 2 * d2 * np.cos(el), el, axis=1)
    return az, width
