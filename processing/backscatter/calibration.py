"""The sonar's calibration as processing reads it, and the processing's own share of it.

An image is calibrated so that a point target of backscatter amplitude ρ (σ_bs = ρ²) at range r,
azimuth θ and elevation φ peaks at

    |I| = G ρ |E_t(θ, φ)| |D(θ, φ)| 10^(−α r / 10) / r²,      G = k S,

with k the ADC scale (counts per unit pressure), S the transmitter's on-axis source level, E_t its
normalised response, D the receiver element's directivity and α the absorption (dB/m). For
scatterers spread through the beam with volume backscattering coefficient s_v, the mean
intensity of the image cell (r, θ_b) is

    E|I|² = s_v G² 10^(−α r / 5) / r² · L_r · Ψ_b,
    Ψ_b = ∫ Φ(θ) |B_b(θ)|² dθ,    Φ(θ) = ∫ |E_t(θ, φ)|² |D(θ, φ)|² cos φ dφ.

The sonar's share — G and the two-way elevation width Φ(θ) — comes from the dataset (/Sonar):
the simulator computes it from its arrays (:mod:`acoustics.sonar.calibration`), a recorded
dataset from its calibration. The processing's share — L_r, the range integral of the
compressed pulse's intensity, and Ψ_b, the beam's two-way equivalent solid angle — is computed
here from the filters and the beamformer. Every user of a calibration (echo integration, Sv,
compensated TS) starts from this module.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from processing.imaging.beamforming import SubarrayGeometry
from processing.imaging.compression import RangeFilter
from processing.base.contract import ENVIRONMENT_GROUP, SONAR_GROUP
from processing.base.dataset import DatasetError, group_of

__all__ = ["absorption_at_carrier", "Calibration", "calibration_of", "range_energy_width_m", "beam_solid_angle_sr"]


@dataclass(frozen=True)
class Calibration:
    """The sonar's part of the echo-integration equation.

    Attributes
    ----------
    gain_counts_m : float
        G: image peak (counts) of a 1 m backscatter amplitude at 1 m on the transmit axis.
    azimuth_rad : ndarray, shape (A,)
    elevation_width_rad : ndarray, shape (A,)
        Φ(θ) = ∫ |E_t|² |D_rx|² cos φ dφ (rad) at each azimuth.
    absorption_db_per_m : float
    """

    gain_counts_m: float
    azimuth_rad: np.ndarray
    elevation_width_rad: np.ndarray
    absorption_db_per_m: float


def calibration_of(tree) -> Calibration:
    """Read the calibration from a dataset's /Sonar and /Environment.

    Raises
    ------
    processing.base.dataset.DatasetError
        The dataset does not carry a calibration (names what is missing and what it means).
    """
    sonar = group_of(tree, SONAR_GROUP)
    missing = [k for k in ("calibration_gain", "two_way_elevation_width")
               if sonar is None or k not in sonar]
    env = group_of(tree, ENVIRONMENT_GROUP)
    if env is None or "absorption_indicative" not in env:
        missing.append(f"/{ENVIRONMENT_GROUP}/absorption_indicative")
    if missing:
        raise DatasetError(
            f"echo integration needs the sonar's calibration: missing {', '.join(missing)} "
            "(/Sonar/calibration_gain: counts x m for a 1 m backscatter amplitude at 1 m on axis; "
            "/Sonar/two_way_elevation_width(calibration_azimuth): rad; see docs/dataset.md)")
    return Calibration(float(sonar["calibration_gain"].values),
                       np.asarray(sonar["calibration_azimuth"].values, float),
                       np.asarray(sonar["two_way_elevation_width"].values, float),
                       absorption_at_carrier(tree))


def absorption_at_carrier(tree) -> float:
    """α (dB/m) at the transmit centre frequency from /Environment/absorption_indicative: a
    scalar, or along ``frequency`` (SONAR-netCDF4), interpolated at
    /Sonar/transmit_frequency_center (the nearest value outside the tabulated range)."""
    a = tree[ENVIRONMENT_GROUP].ds["absorption_indicative"]
    v = np.asarray(a.values, float)
    if v.ndim == 0 or v.size == 1:
        return float(v.ravel()[0])
    f = np.asarray(a["frequency"].values if "frequency" in a.coords else [], float)
    sonar = tree[SONAR_GROUP].ds
    if f.size != v.size or "transmit_frequency_center" not in sonar:
        raise DatasetError("/Environment/absorption_indicative has several values but no frequency "
                           "coordinate (Hz) or no /Sonar/transmit_frequency_center to pick one")
    o = np.argsort(f)
    return float(np.interp(float(sonar["transmit_frequency_center"].values), f[o], v.ravel()[o]))


def range_energy_width_m(rfilter: RangeFilter, sound_speed_m_s: float) -> float:
    """L_r = ∫ |h(r)|² dr (m) of the compressed pulse h, normalised to peak 1.

    By Parseval on the filter's FFT grid: ∫ |h|² dt = mean(|H|²) / fs with h(0) = mean(H) = 1.
    """
    resp = np.asarray(rfilter.response, float)
    return float(np.mean(resp**2) / np.mean(resp) ** 2 / rfilter.rate_hz * sound_speed_m_s / 2)


_SOLID_ANGLES: dict = {}


def beam_solid_angle_sr(calibration: Calibration, geometry: SubarrayGeometry, beam_angle_rad,
                        wavelength_m: float) -> np.ndarray:
    """Ψ_b = ∫ Φ(θ) |B_b(θ)|² dθ (sr) of each beam.

    Parameters
    ----------
    calibration : Calibration
    geometry : SubarrayGeometry
        The image's elements and spatial window (B_b(θ) = Σ w e^{jk x (sinθ − sinθ_b)} / Σ w).
    beam_angle_rad : array_like, shape (n_beams,)
    wavelength_m : float

    Returns
    -------
    ndarray, shape (n_beams,)
    """
    key = (calibration.azimuth_rad.tobytes(), calibration.elevation_width_rad.tobytes(),
           geometry.positions_m.tobytes(), geometry.weights.tobytes(),
           np.asarray(beam_angle_rad, float).tobytes(), float(wavelength_m))
    if key not in _SOLID_ANGLES:   # the same for every ping of a run: computed once per process
        if len(_SOLID_ANGLES) > 16:
            _SOLID_ANGLES.clear()
        _SOLID_ANGLES[key] = _solid_angles(calibration, geometry, beam_angle_rad, wavelength_m)
    return _SOLID_ANGLES[key].copy()


def _solid_angles(calibration, geometry, beam_angle_rad, wavelength_m):
    az = calibration.azimuth_rad
    th = np.linspace(az[0], az[-1], max(20 * az.size, 4001))
    phi = np.interp(th, az, calibration.elevation_width_rad)
    x = geometry.positions_m[:, 0] - geometry.center_m[0]
    w = geometry.weights / geometry.weights.sum()
    k = 2 * np.pi / wavelength_m
    # |B|² depends on sinθ − sinθ_b only: tabulate it once, finer than the θ grid needs
    du = np.linspace(-2.0, 2.0, 80_001)
    af2 = np.abs(np.exp(1j * k * np.outer(du, x)) @ w) ** 2
    s = np.sin(th)
    return np.array([np.trapezoid(phi * np.interp(s - np.sin(tb), du, af2), th)
                     for tb in np.atleast_1d(beam_angle_rad)])
