"""The transmit pulse: an amplitude-tapered LFM chirp in complex baseband.

Thesis eq. 2.24–2.27 (LFM from f0 − B/2 to f0 + B/2 over T, K = B/T) with the amplitude taper
of eq. 4.20, the square root of a Hann window. With the carrier e^{j2πf0 t} removed, the complex
envelope is

    u(t) = a(t/T) · exp(jπK (t − T/2)²),   0 ≤ t ≤ T,   and 0 elsewhere,

whose instantaneous frequency K(t − T/2) sweeps −B/2 → +B/2 (``sweep: down`` reverses it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acoustics.sonar import preset

__all__ = ["TAPERS", "Pulse"]


def _sqrt_hann(x):
    # sqrt(0.5 - 0.5 cos 2πx) = sin(πx) on [0, 1], without a sqrt of rounding noise at the ends
    return np.sin(np.pi * x)


def _hann(x):
    return 0.5 - 0.5 * np.cos(2 * np.pi * x)


def _hamming(x):
    return 0.54 - 0.46 * np.cos(2 * np.pi * x)


def _tukey(x, alpha=0.25):
    w = np.ones_like(x)
    edge = alpha / 2
    lo, hi = x < edge, x > 1 - edge
    w[lo] = 0.5 * (1 - np.cos(np.pi * x[lo] / edge))
    w[hi] = 0.5 * (1 - np.cos(np.pi * (1 - x[hi]) / edge))
    return w


def _rect(x):
    return np.ones_like(x)


#: amplitude tapers a(x) on x = t/T in [0, 1], by name (a registry, as scipy.signal.windows)
TAPERS = {"sqrt_hann": _sqrt_hann, "hann": _hann, "hamming": _hamming, "tukey": _tukey,
          "rectangular": _rect}


@dataclass(frozen=True)
class Pulse:
    """An LFM pulse.

    Attributes
    ----------
    center_frequency_hz : float
        f0 (Hz).
    bandwidth_hz : float
        B (Hz); 0 gives a CW pulse.
    duration_s : float
        T (s).
    taper : str
        Key of :data:`TAPERS`.
    sweep : {"up", "down"}
    """

    center_frequency_hz: float = preset.CENTER_FREQUENCY_HZ
    bandwidth_hz: float = preset.BANDWIDTH_HZ
    duration_s: float = preset.PULSE_DURATION_S
    taper: str = "sqrt_hann"
    sweep: str = "up"

    def __post_init__(self):
        if self.taper not in TAPERS:
            raise ValueError(f"taper must be one of {sorted(TAPERS)}, got {self.taper!r}")
        if self.sweep not in ("up", "down"):
            raise ValueError("sweep must be 'up' or 'down'")
        if not self.duration_s > 0:
            raise ValueError("duration_s must be > 0")

    @classmethod
    def from_spec(cls, spec) -> "Pulse":
        """From a scene's ``signal`` section."""
        return cls(spec.center_frequency_hz, spec.bandwidth_hz, spec.duration_s, spec.taper,
                   spec.sweep)

    @property
    def chirp_rate_hz_s(self) -> float:
        """K = ±B/T (Hz/s), negative for a down-sweep."""
        k = self.bandwidth_hz / self.duration_s
        return k if self.sweep == "up" else -k

    def envelope(self, t_s):
        """Complex envelope u(t).

        Parameters
        ----------
        t_s : array_like
            Times (s) since the pulse started.

        Returns
        -------
        ndarray, complex128, same shape
            Zero outside [0, T]; |u| <= 1.
        """
        t = np.asarray(t_s, float)
        T = self.duration_s
        inside = (t >= 0.0) & (t <= T)
        tc = np.where(inside, t, 0.0)
        a = TAPERS[self.taper](tc / T)
        phase = np.pi * self.chirp_rate_hz_s * (tc - T / 2) ** 2
        return np.where(inside, a * np.exp(1j * phase), 0.0)

    def n_samples(self, rate_hz: float) -> int:
        """Samples of the replica at ``rate_hz``: those at t = j/fs within [0, T]."""
        return int(np.floor(self.duration_s * rate_hz + 1e-9)) + 1

    def replica(self, rate_hz: float):
        """The sampled pulse u(j/fs), j = 0 .. n_samples - 1, complex128, shape (M,).

        This is what processing correlates against (stored in every dataset)."""
        return self.envelope(np.arange(self.n_samples(rate_hz)) / rate_hz)

    @property
    def energy_s(self) -> float:
        """∫|u(t)|² dt (s) of the continuous envelope (sqrt_hann: T/2)."""
        x = np.linspace(0, 1, 20001)
        return float(np.trapezoid(TAPERS[self.taper](x) ** 2, x) * self.duration_s)
