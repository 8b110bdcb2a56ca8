"""Coordinate frames: the thesis' sonar frame and the SONAR-netCDF4 world frame.

Sonar frame (thesis §2.1.1): origin at the array reference point (the transmitter's
phase centre), +z boresight, +x along the receiver subarrays, +y along the transmitter.
Azimuth θ is measured from +z towards +x, elevation φ from the x–z plane towards +y::

    x = r cos φ sin θ,   y = r sin φ,   z = r cos φ cos θ.

World frame: x forward (north), y starboard (east), z down (depth positive); the sea
surface is z = 0. A :class:`Pose` places the sonar frame in the world frame.
See docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["spherical_to_cartesian", "cartesian_to_spherical", "Pose", "transform_rotation"]


def spherical_to_cartesian(range_m, azimuth_rad, elevation_rad):
    """Sonar-frame ⟨r, θ, φ⟩ to Cartesian.

    Parameters
    ----------
    range_m, azimuth_rad, elevation_rad : array_like, broadcastable
        Range (m), azimuth θ (rad, from +z towards +x), elevation φ (rad, towards +y).

    Returns
    -------
    ndarray, shape (..., 3)
        Positions (m) in the sonar frame.
    """
    r, th, ph = np.broadcast_arrays(np.asarray(range_m, float), np.asarray(azimuth_rad, float),
                                    np.asarray(elevation_rad, float))
    cph = np.cos(ph)
    return np.stack([r * cph * np.sin(th), r * np.sin(ph), r * cph * np.cos(th)], axis=-1)


def cartesian_to_spherical(xyz_m):
    """Sonar-frame Cartesian positions to ⟨r, θ, φ⟩.

    Parameters
    ----------
    xyz_m : array_like, shape (..., 3)
        Positions (m) in the sonar frame.

    Returns
    -------
    range_m, azimuth_rad, elevation_rad : ndarray, shape (...)
        At the origin the angles are 0 (not NaN); φ = ±π/2 on the y axis with θ = 0.
    """
    p = np.asarray(xyz_m, float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    r = np.sqrt(x * x + y * y + z * z)
    # atan2 is defined (0) at the origin and stable at ±90°, unlike arcsin(y / r)
    el = np.arctan2(y, np.hypot(x, z))
    az = np.arctan2(x, z)
    return r, az, el


@dataclass(frozen=True, eq=False)
class Pose:
    """The sonar's position and orientation in the world frame.

    Attributes
    ----------
    position_m : ndarray, shape (3,)
        World position (m) of the sonar-frame origin.
    rotation : ndarray, shape (3, 3)
        Proper rotation whose columns are the sonar axes x_s, y_s, z_s written in world
        coordinates, so ``world = position_m + rotation @ sonar``.
    """

    position_m: np.ndarray
    rotation: np.ndarray

    def __post_init__(self):
        p = np.array(self.position_m, float).reshape(3)
        r = np.array(self.rotation, float).reshape(3, 3)
        if not np.allclose(r.T @ r, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
            raise ValueError("Pose.rotation must be a proper rotation matrix")
        p.flags.writeable = False
        r.flags.writeable = False
        object.__setattr__(self, "position_m", p)
        object.__setattr__(self, "rotation", r)

    @classmethod
    def from_axes(cls, position_m, boresight, receiver_axis) -> "Pose":
        """Pose from the world directions of the boresight (+z_s) and receiver axis (+x_s).

        Both directions are normalised; they must be perpendicular (to 1e-6 after
        normalisation). +y_s = z_s × x_s completes a right-handed frame.
        """
        z = np.asarray(boresight, float)
        x = np.asarray(receiver_axis, float)
        nz, nx = np.linalg.norm(z), np.linalg.norm(x)
        if nz == 0 or nx == 0:
            raise ValueError("boresight and receiver_axis must be non-zero vectors")
        z, x = z / nz, x / nx
        if abs(float(z @ x)) > 1e-6:
            raise ValueError("boresight and receiver_axis must be perpendicular")
        y = np.cross(z, x)
        return cls(position_m=np.asarray(position_m, float), rotation=np.column_stack([x, y, z]))

    def to_world(self, xyz_sonar_m):
        """Sonar-frame positions (..., 3) in m to world-frame positions (..., 3) in m."""
        p = np.asarray(xyz_sonar_m, float)
        return p @ self.rotation.T + self.position_m

    def to_sonar(self, xyz_world_m):
        """World-frame positions (..., 3) in m to sonar-frame positions (..., 3) in m."""
        p = np.asarray(xyz_world_m, float)
        return (p - self.position_m) @ self.rotation

    def direction_to_world(self, v_sonar):
        """Rotate directions (..., 3) from the sonar frame to the world frame."""
        return np.asarray(v_sonar, float) @ self.rotation.T


def transform_rotation(rotate_deg) -> np.ndarray:
    """The rotation of a mesh's ``transform.rotate_deg``: about x, then y, then z (degrees,
    right-handed), R = R_z R_y R_x, shape (3, 3)."""
    rx, ry, rz = np.radians(rotate_deg)
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    r_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    r_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    r_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return r_z @ r_y @ r_x
