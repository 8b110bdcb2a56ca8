"""What the receiver adds after the water: noise and the ADC (each only when asked for).

Noise (thesis §2.4.2, §3.5.1): complex white Gaussian noise band-limited to the receiver band
[−B_n/2, B_n/2] about the carrier, independent across channels, with standard deviation σ in
each quadrature component *after* band-limiting (σ = 126.68 ADC counts in the thesis): white
noise at fs through an ideal, zero-phase filter on the circular record (the FFT bins outside the
band zeroed), scaled so that E|I|² = E|Q|² = σ². The DFT of white complex Gaussian noise is
white complex Gaussian noise, so the in-band bins are drawn directly and inverted once — the same
distribution as filtering a white record, at one FFT instead of two and a fraction of the draws.

ADC (thesis §3.4.1, §3.6): samples are already in counts (the scale k is part of the echo
amplitude). Quantisation rounds I and Q to integers and clips them to the signed range of the
converter, [−2^(b−1), 2^(b−1) − 1]; clipped samples are counted per channel.
"""
from __future__ import annotations

import numpy as np

__all__ = ["band_limited_noise", "quantize"]


def band_limited_noise(rng: np.random.Generator, n_channels: int, n_samples: int, *,
                       sigma_counts: float, bandwidth_hz: float, rate_hz: float):
    """Independent band-limited complex Gaussian noise for every channel.

    Parameters
    ----------
    rng : numpy.random.Generator
        Seeded per ping (stream "noise").
    n_channels, n_samples : int
    sigma_counts : float
        Standard deviation (counts) of each of I and Q after band-limiting; 0 gives zeros.
    bandwidth_hz : float
        Two-sided receiver band B_n (Hz); clipped to fs.
    rate_hz : float
        Sampling rate fs (Hz).

    Returns
    -------
    ndarray, shape (n_channels, n_samples), complex128
    """
    if sigma_counts == 0 or n_samples == 0:
        return np.zeros((n_channels, n_samples), complex)
    freqs = np.fft.fftfreq(n_samples, 1.0 / rate_hz)
    keep = np.abs(freqs) <= min(bandwidth_hz, rate_hz) / 2
    frac = keep.mean()
    if frac == 0:
        raise ValueError(f"noise band {bandwidth_hz:g} Hz keeps no frequency bin of a "
                         f"{n_samples}-sample record at {rate_hz:g} Hz")
    if frac == 1:
        white = rng.standard_normal((n_channels, n_samples, 2))
        return (white[..., 0] + 1j * white[..., 1]) * sigma_counts
    bins = np.flatnonzero(keep)
    white = rng.standard_normal((n_channels, bins.size, 2))
    spec = np.zeros((n_channels, n_samples), complex)
    spec[:, bins] = white[..., 0] + 1j * white[..., 1]
    # K unit bins give each component of the inverse DFT (1/N Σ) the variance K/N²
    return np.fft.ifft(spec, axis=1) * (sigma_counts * n_samples / np.sqrt(bins.size))


def quantize(x, bits: int):
    """Round to integers and clip to a signed ``bits``-bit range, I and Q separately.

    Parameters
    ----------
    x : ndarray, complex, shape (..., n_samples)
    bits : int

    Returns
    -------
    q : ndarray, complex128, same shape
        Integer-valued I and Q.
    clipped : ndarray of int, shape x.shape[:-1]
        Number of samples per channel in which I or Q was clipped.
    """
    lo, hi = -(2 ** (bits - 1)), 2 ** (bits - 1) - 1
    re, im = np.rint(x.real), np.rint(x.imag)
    over = (re < lo) | (re > hi) | (im < lo) | (im > hi)
    q = np.clip(re, lo, hi) + 1j * np.clip(im, lo, hi)
    return q, over.sum(axis=-1)
