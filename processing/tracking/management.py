"""The track-management part of the tracker: how tracks are born, confirmed and ended.

M-of-N logic (Blackman & Popoli 1999, §3.2): every detection no track takes starts a tentative
track; the track is confirmed once it holds ``confirm_hits`` (M) detections within its first
``confirm_window`` (N) pings, dropped as soon as that can no longer happen, and ended after
``max_misses`` consecutive pings without a detection (a confirmed track is kept, a tentative one
forgotten). A new track starts at its detection, still, with a velocity spread of
``initial_speed_sd_m_s`` per axis: the speed of fish it expects, which with the ping interval
sets the gate of its second detection.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MOfN"]


@dataclass(frozen=True)
class MOfN:
    """M-of-N confirmation and deletion after consecutive misses.

    Attributes
    ----------
    confirm_hits, confirm_window : int
        M and N.
    max_misses : int
        Consecutive misses after which a track ends.
    initial_speed_sd_m_s : float
        Velocity spread (m/s per axis) of a new track.
    """

    confirm_hits: int = 3
    confirm_window: int = 4
    max_misses: int = 2
    initial_speed_sd_m_s: float = 0.5

    def __post_init__(self):
        if self.confirm_window < self.confirm_hits:
            raise ValueError(f"confirm_window ({self.confirm_window}) must be at least "
                             f"confirm_hits ({self.confirm_hits})")

    def birth(self, z_m, R_m2):
        """State (6,) and covariance (6, 6) of a track born at detection ``z_m`` (3,) (m) with
        covariance ``R_m2`` (3, 3)."""
        P0 = np.zeros((6, 6))
        P0[:3, :3] = R_m2
        P0[3:, 3:] = np.eye(3) * self.initial_speed_sd_m_s ** 2
        return np.concatenate([np.asarray(z_m, float), np.zeros(3)]), P0

    def confirmed(self, hits: int, age: int) -> bool:
        """Whether a tentative track of ``age`` pings holding ``hits`` detections is confirmed."""
        return hits >= self.confirm_hits and age <= self.confirm_window

    def hopeless(self, hits: int, age: int) -> bool:
        """Whether a tentative track can no longer be confirmed."""
        return hits + max(0, self.confirm_window - age) < self.confirm_hits

    def ended(self, misses: int) -> bool:
        """Whether a track with ``misses`` consecutive misses ends."""
        return misses > self.max_misses
