"""The scatterers a ping's echoes are synthesised from: one structure for every path kind.

Point targets, multipath images, boundary facets and mesh-target facets all become *virtual
scatterers*: a transmit-leg end point, a receive-leg start point (different from it when the
path bounces on its way back) and a complex strength (m). The synthesis stage sees only these.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["VirtualScatterers"]


@dataclass
class VirtualScatterers:
    """Scatterers with separate transmit-leg and receive-leg points.

    Attributes
    ----------
    p_tx, p_rx : ndarray, shape (S, 3)
        Sonar-frame points (m) whose distances and directions define each leg.
    strength : ndarray, shape (S,), complex
        Backscatter amplitude (m), reflection coefficients included.
    kind : ndarray of str, shape (S,)
        "direct", "multipath", "reverberation", "mesh_target".
    rate_m_s : ndarray, shape (S,), or None
        d(path length)/dt (m/s) of each path, transmit leg + receive leg: its Doppler shift is
        f_d = −f0 (dL/dt) / c. None where the path kind was not asked for its rates (no
        Doppler); :meth:`concat` gives such parts rate 0 beside parts that have rates.
    """

    p_tx: np.ndarray
    p_rx: np.ndarray
    strength: np.ndarray
    kind: np.ndarray
    rate_m_s: np.ndarray | None = None

    @classmethod
    def empty(cls):
        z = np.zeros((0, 3))
        return cls(z, z.copy(), np.zeros(0, complex), np.zeros(0, "<U13"))

    @classmethod
    def concat(cls, parts):
        parts = [p for p in parts if p is not None and len(p.strength)]
        if not parts:
            return cls.empty()
        rates = None
        if any(p.rate_m_s is not None for p in parts):
            rates = np.concatenate([p.rate_m_s if p.rate_m_s is not None else np.zeros(len(p))
                                    for p in parts])
        return cls(np.concatenate([p.p_tx for p in parts]), np.concatenate([p.p_rx for p in parts]),
                   np.concatenate([p.strength for p in parts]), np.concatenate([p.kind for p in parts]),
                   rates)

    def doppler_hz(self, center_frequency_hz: float, sound_speed_m_s: float) -> np.ndarray | None:
        """Each path's Doppler shift f_d = −f0 (dL/dt) / c (Hz), shape (S,); None without rates."""
        if self.rate_m_s is None:
            return None
        return -np.asarray(self.rate_m_s, float) * center_frequency_hz / sound_speed_m_s

    def __len__(self):
        return int(self.strength.shape[0])
