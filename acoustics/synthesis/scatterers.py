"""The scatterers a ping's echoes are synthesised from: one structure for every path kind.

Point targets, multipath images, boundary facets and mesh-target facets all become *virtual
scatterers*: a transmit-leg end point, a receive-leg start point (different from it when the
path bounces on its way back) and a complex strength (m). The synthesis stage sees only these.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["VirtualScatterers", "PathTags"]


@dataclass
class PathTags:
    """What each path is, for the arrivals table (only when a run records arrivals).

    Attributes
    ----------
    target : ndarray of int, shape (S,)
        Row of the ping's target set whose echo the path carries (−1: a facet, not a target).
    sequence : ndarray of str, shape (S,)
        Interactions in propagation order (docs/dataset.md, "Arrivals"): ``T`` the target,
        ``S``/``F``/``O`` a specular bounce off a surface, floor or obstacle, ``RS``/``RF``/``RO``
        a surface's, floor's or obstacle's facet (reverberation), ``M`` a mesh target's facet; joined by ``-`` (``S-T-F``). Empty: not yet known.
    via : ndarray of str, shape (S,)
        The boundaries bounced off, in order, ``;``-separated (``name#facet`` for a curved one).
    """

    target: np.ndarray
    sequence: np.ndarray
    via: np.ndarray

    @classmethod
    def unknown(cls, n: int):
        return cls(np.full(n, -1, np.int64), np.full(n, "", dtype=object).astype(str),
                   np.full(n, "", dtype=object).astype(str))

    @classmethod
    def concat(cls, parts):
        return cls(*(np.concatenate([getattr(p, f) for p in parts])
                     for f in ("target", "sequence", "via")))


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
    tags : PathTags or None
        What each path is (only when the run records arrivals).
    """

    p_tx: np.ndarray
    p_rx: np.ndarray
    strength: np.ndarray
    kind: np.ndarray
    rate_m_s: np.ndarray | None = None
    tags: PathTags | None = None

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
        tags = None
        if any(p.tags is not None for p in parts):
            tags = PathTags.concat([p.tags if p.tags is not None else PathTags.unknown(len(p))
                                    for p in parts])
        return cls(np.concatenate([p.p_tx for p in parts]), np.concatenate([p.p_rx for p in parts]),
                   np.concatenate([p.strength for p in parts]), np.concatenate([p.kind for p in parts]),
                   rates, tags)

    def doppler_hz(self, center_frequency_hz: float, sound_speed_m_s: float) -> np.ndarray | None:
        """Each path's Doppler shift f_d = −f0 (dL/dt) / c (Hz), shape (S,); None without rates."""
        if self.rate_m_s is None:
            return None
        return -np.asarray(self.rate_m_s, float) * center_frequency_hz / sound_speed_m_s

    def __len__(self):
        return int(self.strength.shape[0])
