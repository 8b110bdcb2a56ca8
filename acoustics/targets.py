"""Point targets: explicit positions and random populations, seeded per ping."""
from __future__ import annotations

import numpy as np

from .frames import Pose, spherical_to_cartesian

__all__ = ["point_positions_sonar"]


def point_positions_sonar(points, pose: Pose) -> np.ndarray:
    """Sonar-frame positions (m), shape (n, 3), of explicit point-target specs."""
    out = np.zeros((len(points), 3))
    for i, t in enumerate(points):
        if t.position_m is None:
            out[i] = spherical_to_cartesian(t.range_m, t.azimuth, t.elevation)
        elif t.frame == "sonar":
            out[i] = t.position_m
        else:
            out[i] = pose.to_sonar(np.asarray(t.position_m, float))
    return out
