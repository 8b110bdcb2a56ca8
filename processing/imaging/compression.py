"""Pulse compression (thesis §4.1–4.3) and band-limited interpolation (§4.4).

Each channel is correlated with the replica u (the matched filter h(t) = u*(−t), eq. 4.4) by FFT,
weighted in frequency by a range window over the pulse band [−B/2, B/2] (eq. 4.19; Hamming by
default, as §4.3.3 proposes) and interpolated by zero-padding the spectrum (§4.4), all in one pass:

    Y(f) = X(f) · U*(f) · W(f) / G,    G = mean_f |U(f)|² W(f)

The FFT is long enough (≥ N + M − 1) for the correlation to be linear. Time origin: output
sample i is at t0 + i/(U fs), and the compressed peak of an echo that *starts* at τ lands at
t = τ, the two-way delay (eq. 4.7). The normalisation G makes the filter calibrated: an echo of
complex amplitude A (per element, ADC counts) gives a compressed peak of exactly A.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

__all__ = ["WINDOWS", "window", "RangeFilter", "compressed_spectra", "to_time", "compress"]

#: window names accepted in settings -> scipy.signal.get_window spec (a registry)
WINDOWS = {"rectangular": "boxcar", "hamming": "hamming", "hann": "hann",
           "taylor": ("taylor", 4, 35), "blackman": "blackman"}


_NUMPY_WINDOWS = {"rectangular": np.ones, "hamming": np.hamming, "hann": np.hanning,
                  "blackman": np.blackman}


def window(name: str, n: int) -> np.ndarray:
    """Symmetric window of ``n`` points by name (:data:`WINDOWS`), peak 1."""
    if name not in WINDOWS:
        raise ValueError(f"window must be one of {sorted(WINDOWS)}, got {name!r}")
    if n <= 0:
        return np.zeros(0)
    if n == 1:
        return np.ones(1)
    if name in _NUMPY_WINDOWS:  # the same symmetric formulas, without importing scipy.signal
        w = _NUMPY_WINDOWS[name](n)
    else:
        from scipy.signal import get_window
        w = get_window(WINDOWS[name], n, fftbins=False)
    if not w.max() > 0:  # a 2-point Hann is all zeros: too short to taper, leave it untapered
        return np.ones(n)
    return w / w.max()


@dataclass(frozen=True, eq=False)
class RangeFilter:
    """The matched filter with its range window for one record geometry (cached work).

    Attributes
    ----------
    spectrum : ndarray, shape (nfft,), complex128
        U*(f) W(f) / G on the FFT grid of length ``nfft``.
    nfft : int
    band_mask : ndarray of bool, shape (nfft,)
        Bins inside [−B/2, B/2].
    """

    spectrum: np.ndarray
    nfft: int
    band_mask: np.ndarray
    rate_hz: float
    response: np.ndarray | None = None
    """|U(f)|² W(f) / G: the spectrum of the compressed pulse (the range point response)."""

    @classmethod
    def design(cls, replica, *, n_samples: int, rate_hz: float, bandwidth_hz: float,
               range_window: str = "hamming") -> "RangeFilter":
        """Filter for records of ``n_samples`` at ``rate_hz`` and a replica (shape (M,))."""
        rep = np.asarray(replica, complex)
        if rep.size == 0 or not np.any(rep):
            raise ValueError("the replica is empty or all zero")
        nfft = sfft.next_fast_len(n_samples + rep.size - 1)
        u = sfft.fft(rep, nfft)
        f = sfft.fftfreq(nfft, 1.0 / rate_hz)
        # the pulse band; a CW pulse (B = 0) still occupies about ±1/T
        half = max(bandwidth_hz / 2, rate_hz / rep.size)
        band = np.abs(f) <= half
        w = np.zeros(nfft)
        idx = np.flatnonzero(band)
        order = idx[np.argsort(f[idx])]
        w[order] = window(range_window, order.size)
        h = np.conj(u) * w
        g = np.mean(np.abs(u) ** 2 * w)
        if not g > 0:
            raise ValueError("the range window removes the whole pulse band")
        return cls(h / g, nfft, band, float(rate_hz), np.abs(u) ** 2 * w / g)

    def noise_power_gain(self, noise_band_hz: float | None = None) -> float:
        """Output/input noise power for white noise confined to ``noise_band_hz`` (two-sided,
        centred; None = the whole sampled band) and of equal total power."""
        f = sfft.fftfreq(self.nfft, 1.0 / self.rate_hz)
        inside = np.ones(self.nfft, bool) if noise_band_hz is None else np.abs(f) <= noise_band_hz / 2
        psd = inside / inside.mean()
        return float(np.mean(psd * np.abs(self.spectrum) ** 2))


def compressed_spectra(samples, rfilter: RangeFilter):
    """Spectra (length nfft) of the matched-filtered, range-weighted channels.

    Parameters
    ----------
    samples : array_like, shape (..., N), complex

    Returns
    -------
    ndarray, shape (..., nfft), complex128
    """
    # double precision whatever the storage (float32 pairs on disk, complex64 in a record)
    spec = sfft.fft(np.asarray(samples, np.complex128), rfilter.nfft, axis=-1)
    spec *= rfilter.spectrum
    return spec


def to_time(spectra, rfilter: RangeFilter, *, upsample: int = 1, keep=None):
    """Back to time, interpolated ``upsample`` times by zero-padding the band-limited spectrum.

    Parameters
    ----------
    spectra : ndarray, shape (..., nfft), complex
    upsample : int
        U >= 1.
    keep : slice, optional
        Output samples (interpolated grid) to return; default all.

    Returns
    -------
    ndarray, shape (..., n_keep), complex128
        Sample i at t0 + i/(U fs); amplitudes calibrated.
    """
    up = int(upsample)
    if up < 1:
        raise ValueError(f"interpolation factor must be >= 1, got {upsample}")
    if up > 1:
        out = sfft.ifft(_zero_padded(spectra, rfilter.nfft, up), axis=-1, overwrite_x=True)
    else:
        # double precision as documented, also for spectra stored in single precision
        out = sfft.ifft(np.asarray(spectra, np.complex128), axis=-1)
    return out if keep is None else out[..., keep]


def _zero_padded(spectra, n: int, up: int):
    """The spectra (length n) zero-padded to n·U and scaled by U, shape (..., n·U), complex128."""
    big = np.empty(np.shape(spectra)[:-1] + (n * up,), np.complex128)
    h = (n + 1) // 2
    tail = n * up - (n - h)
    # the band's two halves are written scaled; only the gap between them needs zeros
    np.multiply(spectra[..., :h], up, out=big[..., :h], dtype=np.complex128)
    big[..., h:tail] = 0
    np.multiply(spectra[..., h:], up, out=big[..., tail:], dtype=np.complex128)
    return big


def compress(samples, rfilter: RangeFilter, *, upsample: int = 1, keep=None):
    """Matched-filter, range-window and interpolate every channel.

    Parameters
    ----------
    samples : array_like, shape (..., N), complex
        Per-element baseband samples.
    rfilter : RangeFilter
    upsample : int
        Interpolation factor U >= 1 (band-limited, by zero-padding the spectrum).
    keep : slice, optional
        Output samples (on the interpolated grid) to return; default the N·U samples of the
        record.

    Returns
    -------
    ndarray, shape (..., n_keep), complex128
        Output sample i is at t0 + i/(U fs); amplitudes are calibrated (an echo of amplitude A
        peaks at A).
    """
    x = np.asarray(samples)
    keep = keep if keep is not None else slice(0, x.shape[-1] * int(upsample))
    return to_time(compressed_spectra(x, rfilter), rfilter, upsample=upsample, keep=keep)
