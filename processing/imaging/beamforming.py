"""Beamforming across a receiver subarray (thesis §4.5): FFT, delay-and-sum, wideband.

Signal model (docs/conventions.md): a plane wave from azimuth θ reaches element n at
x_n earlier by (x_n − x_c) sin θ / c than the subarray's phase centre x_c, so its baseband sample
carries e^{+jk(x_n − x_c) sin θ}. Steering to θ_m multiplies by the conjugate and sums:

    B(θ_m) = Σ_n w_n y_n e^{−jk (p_n − p_c)·û(θ_m)} / Σ_n w_n            (eq. 4.35, 4.44)

so a target on a beam's axis keeps the phase of its path to the phase centre, as interferometry
needs, and amplitudes stay calibrated (a plane wave of amplitude A per element gives A).

``fft``
    the array's uniform pitch d makes this a DFT (eq. 4.36–4.39): zero-pad to n_beams, FFT,
    multiply by the phase-centre correction e^{−jk(x_0 − x_c) sin θ_m} (eq. 4.40). Its beams sit
    at sin θ_m = m λ / (n_beams d), m = −n/2 .. n/2 − 1, spanning the grating-lobe-free ±λ/2d.
``delay_and_sum``
    the same sum at any angles with each element's exact position (non-uniform arrays too).
``wideband``
    true time delays: each element's spectrum is shifted by e^{j2π(f0 + f)δ_n(θ)}, i.e. the
    exact phase at every frequency of the band, not only at the carrier (§4.5.8). The reference
    setting when B/f0 is not small.
"""
from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from processing.imaging.compression import window

__all__ = ["BEAMFORMERS", "SubarrayGeometry", "fft_beam_angles", "default_beam_angles",
           "beamform_fft", "beamform_das", "beamform_wideband"]

BEAMFORMERS = ("fft", "delay_and_sum", "wideband")


class SubarrayGeometry:
    """Elements of one image, sorted along x, with weights and phase centre.

    Parameters
    ----------
    positions_m : array_like, shape (n, 3)
        Element centres (m), sonar frame.
    spatial_window : str
        Across-array weighting by name.
    """

    def __init__(self, positions_m, spatial_window: str = "hamming"):
        p = np.asarray(positions_m, float).reshape(-1, 3)
        if p.shape[0] == 0:
            raise ValueError("a subarray needs at least one element")
        self.order = np.argsort(p[:, 0], kind="stable")
        #: whether the elements came sorted (their order needs no gather)
        self.sorted = bool(np.all(self.order == np.arange(self.order.size)))
        self.positions_m = p[self.order]
        self.weights = window(spatial_window, p.shape[0])
        self.center_m = self.positions_m.mean(axis=0)
        #: (n_beams, wavelength) -> (angles, correction per DFT bin) of :func:`beamform_fft`
        self.fft_plans: dict = {}

    @property
    def n_elements(self) -> int:
        return self.positions_m.shape[0]

    @property
    def pitch_m(self) -> float:
        """Mean element spacing along x (m)."""
        x = self.positions_m[:, 0]
        return float((x[-1] - x[0]) / (x.size - 1)) if x.size > 1 else float("inf")

    def is_uniform(self, rtol: float = 1e-6) -> bool:
        x = self.positions_m[:, 0]
        if x.size < 2:
            return True
        d = np.diff(x)
        return bool(np.all(np.abs(d - d.mean()) <= rtol * abs(d.mean())) and d.mean() > 0)

    def noise_power_gain(self) -> float:
        """Beamformer output/input noise power for independent channels: Σw² / (Σw)²."""
        w = self.weights
        return float((w**2).sum() / w.sum() ** 2)


def fft_beam_angles(n_beams: int, pitch_m: float, wavelength_m: float) -> np.ndarray:
    """Beam angles (rad), ascending, of an n-point FFT beamformer: sin θ_m = m λ/(n d)."""
    m = np.arange(-(n_beams // 2), n_beams - n_beams // 2)
    s = m * wavelength_m / (n_beams * pitch_m)
    return np.arcsin(np.clip(s, -1.0, 1.0))


def default_beam_angles(geometry: SubarrayGeometry, wavelength_m: float, *, n_beams=None,
                        span_rad=None) -> np.ndarray:
    """Beams uniform in sin θ over the span (default the grating-lobe-free ±arcsin(λ/2d)),
    as many as the spatial Nyquist rate needs (default: 2 per resolution width, rounded up to a
    power of two) unless ``n_beams`` is given."""
    d = geometry.pitch_m
    half = np.arcsin(min(1.0, wavelength_m / (2 * d))) if span_rad is None else span_rad / 2
    if n_beams is None:
        aperture = geometry.n_elements * d
        need = 2 * 2 * np.sin(half) * aperture / wavelength_m
        n_beams = int(2 ** np.ceil(np.log2(max(need, 2))))
    u = np.sin(half) * (2 * np.arange(n_beams) - n_beams) / n_beams  # like the FFT grid
    return np.arcsin(u)


def _steering(geometry: SubarrayGeometry, angles_rad, k):
    """e^{−jk (p_n − p_c)·û(θ)} for every beam and element, shape (n_beams, n_el)."""
    th = np.asarray(angles_rad, float)
    u = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], -1)
    return np.exp(-1j * k * ((geometry.positions_m - geometry.center_m) @ u.T).T)


def beamform_das(y, geometry: SubarrayGeometry, angles_rad, wavelength_m: float):
    """Narrowband delay-and-sum with exact per-element phases.

    Parameters
    ----------
    y : ndarray, shape (..., n_el, n_range), complex
        Compressed channels of this subarray, in the order the geometry was given.
    geometry : SubarrayGeometry
    angles_rad : array_like, shape (n_beams,)
    wavelength_m : float
        λ at the carrier.

    Returns
    -------
    ndarray, shape (..., n_range, n_beams), complex128
    """
    a = _steering(geometry, angles_rad, 2 * np.pi / wavelength_m) * geometry.weights
    a /= geometry.weights.sum()
    ys = np.asarray(y)[..., geometry.order, :]
    return np.einsum("bn,...nr->...rb", a, ys)


def beamform_fft(y, geometry: SubarrayGeometry, n_beams: int, wavelength_m: float, *, beams=None,
                 out=None):
    """FFT beamforming with zero-padding and the phase-centre correction (eq. 4.36–4.40).

    Parameters
    ----------
    y : ndarray, shape (..., n_el, n_range), complex
        Compressed channels of this subarray, in the order the geometry was given.
    geometry : SubarrayGeometry
        Uniformly spaced elements.
    n_beams : int
        FFT length (>= n_el): the beams of :func:`fft_beam_angles`.
    wavelength_m : float
        λ at the carrier (m).
    beams : ndarray of int, shape (n_sel,), optional
        The beams to form, as indices into the ascending angles; default all.
    out : ndarray, shape (..., n_range, n_sel), complex128, optional
        Where to write the image.

    Returns
    -------
    angles_rad : ndarray, shape (n_sel,)
    image : ndarray, shape (..., n_range, n_sel), complex128
    """
    angles, corr = _fft_plan(geometry, int(n_beams), float(wavelength_m))
    n_el = geometry.n_elements
    if n_beams < n_el:
        raise ValueError(f"FFT beamforming needs n_beams >= the {n_el} elements")
    y = np.asarray(y)
    ys = np.swapaxes(y if geometry.sorted else y[..., geometry.order, :], -1, -2) * geometry.weights
    # the DFT along the last axis leaves beams contiguous per range sample, the image's layout
    spec = sfft.fft(ys, n_beams, axis=-1)          # (..., n_range, n_beams), DFT bin order
    spec *= corr
    sel = np.arange(n_beams) if beams is None else np.asarray(beams, int)
    # the ascending beam m sits in DFT bin (m − n/2) mod n: fftshift as a gather of the kept beams
    bins = (sel - n_beams // 2) % n_beams
    # mode "wrap" (the indices are in range anyway) lets np.take write into ``out`` unbuffered
    img = np.take(spec, bins, axis=-1, out=out, mode="wrap")
    return angles[sel], img


def _fft_plan(geometry: SubarrayGeometry, n_beams: int, wavelength_m: float):
    """Ascending beam angles (n_beams,) and the phase-centre correction of each DFT bin
    (n_beams,), remembered per geometry (a record is beamformed ping after ping)."""
    key = (n_beams, wavelength_m)
    if key not in geometry.fft_plans:
        if not geometry.is_uniform():
            raise ValueError("FFT beamforming needs uniformly spaced elements; use delay_and_sum")
        k = 2 * np.pi / wavelength_m
        angles = fft_beam_angles(n_beams, geometry.pitch_m, wavelength_m)
        x0 = geometry.positions_m[0] - geometry.center_m
        u = np.stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)], -1)
        # the DFT's phase refers to element 0 along x only; move it to the phase centre
        corr = np.exp(-1j * k * (u @ x0)) / geometry.weights.sum()
        geometry.fft_plans[key] = (angles, np.fft.ifftshift(corr))
    return geometry.fft_plans[key]


def beamform_wideband(spectra, geometry: SubarrayGeometry, angles_rad, *, wavelength_m: float,
                      sound_speed_m_s: float, center_frequency_hz: float, rate_hz: float):
    """True-time-delay beamforming in the frequency domain.

    Parameters
    ----------
    spectra : ndarray, shape (..., n_el, nfft), complex
        FFTs (length nfft, sampling rate ``rate_hz``) of the compressed channels.

    Returns
    -------
    ndarray, shape (..., n_beams, nfft), complex128
        Spectra of the beams; invert and interpolate as for a channel.
    """
    th = np.asarray(angles_rad, float)
    u = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], -1)
    # arrival advance of each element relative to the phase centre, per beam (s)
    delta = -((geometry.positions_m - geometry.center_m) @ u.T).T / sound_speed_m_s  # (b, n)
    nfft = spectra.shape[-1]
    f = center_frequency_hz + sfft.fftfreq(nfft, 1.0 / rate_hz)
    w = geometry.weights / geometry.weights.sum()
    ys = np.asarray(spectra)[..., geometry.order, :]
    out = np.empty(ys.shape[:-2] + (th.size, nfft), complex)
    for b in range(th.size):
        steer = np.exp(2j * np.pi * f[None, :] * delta[b][:, None]) * w[:, None]  # (n, nfft)
        out[..., b, :] = np.einsum("nf,...nf->...f", steer, ys)
    return out
