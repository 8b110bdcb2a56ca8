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
    """

    p_tx: np.ndarray
    p_rx: np.ndarray
    strength: np.ndarray
    kind: np.ndarray

    @classmethod
    def empty(cls):
        z = np.zeros((0, 3))
        return cls(z, z.copy(), np.zeros(0, complex), np.zeros(0, "<U13"))

    @classmethod
    def concat(cls, parts):
        parts = [p for p in parts if p is not None and len(p.strength)]
        if not parts:
            return cls.empty()
        return cls(np.concatenate([p.p_tx for p in parts]), np.concatenate([p.p_rx for p in parts]),
                   np.concatenate([p.strength for p in parts]), np.concatenate([p.kind for p in parts]))

    def __len__(self):
        return int(self.strength.shape[0])
