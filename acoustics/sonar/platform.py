"""The moving platform: roll, pitch, yaw and heave per ping, and the sonar pose they give.

Conventions (docs/conventions.md): the vessel frame is the world frame at rest (x forward, y
starboard, z down). Roll turns about x (starboard down positive), pitch about y (bow up
positive), yaw about z (clockwise seen from above positive); the attitude is
R = R_z(yaw) R_y(pitch) R_x(roll), the aerospace/ship Z-Y-X order. The sonar is mounted at
``sonar.pose`` in the vessel frame and turns with it about the vessel's reference point (the
world origin); heave (positive up) lifts the whole vessel: world z − heave.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from acoustics.frames import Pose

__all__ = ["attitude_rotation", "PlatformMotion", "read_motion_csv", "MotionFileError", "pose_at_time_zero"]

_COLUMNS = ("time_s", "roll_deg", "pitch_deg", "yaw_deg", "heave_m")


class MotionFileError(ValueError):
    """A motion CSV that cannot be read (the message names the file, line and column)."""


def attitude_rotation(roll_rad, pitch_rad, yaw_rad) -> np.ndarray:
    """R = R_z(yaw) R_y(pitch) R_x(roll), shape (3, 3) (or (..., 3, 3) for arrays)."""
    r, p, y = (np.asarray(a, float) for a in (roll_rad, pitch_rad, yaw_rad))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    out = np.empty(np.broadcast(r, p, y).shape + (3, 3))
    out[..., 0, 0] = cy * cp
    out[..., 0, 1] = cy * sp * sr - sy * cr
    out[..., 0, 2] = cy * sp * cr + sy * sr
    out[..., 1, 0] = sy * cp
    out[..., 1, 1] = sy * sp * sr + cy * cr
    out[..., 1, 2] = sy * sp * cr - cy * sr
    out[..., 2, 0] = -sp
    out[..., 2, 1] = cp * sr
    out[..., 2, 2] = cp * cr
    return out


def read_motion_csv(path: Path) -> dict:
    """Columns of a motion CSV (header ``time_s`` and any of roll_deg, pitch_deg, yaw_deg,
    heave_m), as float arrays.

    Raises
    ------
    MotionFileError
    """
    import csv
    out: dict = {}
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError) as exc:
        raise MotionFileError(f"{path}: cannot be read as CSV text ({exc.__class__.__name__})") from None
    if not rows:
        raise MotionFileError(f"{path}: empty; expected a header row with time_s")
    head = [h.strip() for h in rows[0]]
    unknown = [h for h in head if h not in _COLUMNS]
    if "time_s" not in head or unknown:
        raise MotionFileError(f"{path}:1: header must name time_s and any of {', '.join(_COLUMNS[1:])}"
                              + (f" (unknown: {', '.join(unknown[:3])})" if unknown else ""))
    cols = {h: [] for h in head}
    for i, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) != len(head):
            raise MotionFileError(f"{path}:{i}: {len(row)} values for {len(head)} columns")
        for h, c in zip(head, row):
            try:
                v = float(c)
            except ValueError:
                raise MotionFileError(f"{path}:{i}: column {h}: not a number") from None
            if not math.isfinite(v):
                raise MotionFileError(f"{path}:{i}: column {h}: not a finite number")
            cols[h].append(v)
    out = {h: np.asarray(v, float) for h, v in cols.items()}
    t = out["time_s"]
    if t.size == 0 or np.any(np.diff(t) <= 0):
        raise MotionFileError(f"{path}: time_s must hold at least one time and increase strictly")
    return out


@dataclass(frozen=True)
class PlatformMotion:
    """Attitude and heave as functions of time, and the sonar pose they give.

    Attributes
    ----------
    time_s : ndarray, shape (T,)
    roll_rad, pitch_rad, yaw_rad : ndarray, shape (T,)
    heave_m : ndarray, shape (T,)
        Positive up.
    swell : object or None
        A :class:`~acoustics.scene.motion_spec.SwellSpec` (analytic), else the series is used.
    """

    time_s: np.ndarray
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    yaw_rad: np.ndarray
    heave_m: np.ndarray
    swell: object = None

    @classmethod
    def from_spec(cls, spec, resolve) -> "PlatformMotion":
        """From a scene's ``sonar.motion``; ``resolve`` turns a path in the scene into a file."""
        z = np.zeros(1)
        if spec.kind == "swell":
            return cls(z, z, z, z, z, spec.swell)
        if spec.kind == "series":
            s = spec.series
            cols = {"time_s": s.time_s, "roll_deg": s.roll_deg, "pitch_deg": s.pitch_deg,
                    "yaw_deg": s.yaw_deg, "heave_m": s.heave_m}
        else:
            cols = read_motion_csv(resolve(spec.file))
        t = np.asarray(cols["time_s"], float)

        def col(name, scale=1.0):
            v = cols.get(name)
            return np.zeros_like(t) if v is None else np.asarray(v, float) * scale
        return cls(t, col("roll_deg", math.pi / 180), col("pitch_deg", math.pi / 180),
                   col("yaw_deg", math.pi / 180), col("heave_m"))

    def attitude(self, t_s):
        """(roll, pitch, yaw) in rad and heave in m at times ``t_s`` (s after ping 0)."""
        t = np.asarray(t_s, float)
        if self.swell is not None:
            s = self.swell
            return (s.roll_amplitude * np.sin(2 * np.pi * t / s.roll_period_s),
                    s.pitch_amplitude * np.sin(2 * np.pi * t / s.pitch_period_s),
                    np.zeros_like(t),
                    s.heave_amplitude_m * np.sin(2 * np.pi * t / s.heave_period_s))
        # linear between samples; held at the ends; yaw unwrapped so 359° → 1° turns by 2°
        yaw = np.unwrap(self.yaw_rad)
        return tuple(np.interp(t, self.time_s, v) for v in (self.roll_rad, self.pitch_rad, yaw,
                                                             self.heave_m))

    def pose(self, mount: Pose, t_s: float) -> Pose:
        """The sonar's world pose at time ``t_s``."""
        roll, pitch, yaw, heave = (float(v) for v in self.attitude(t_s))
        rot = attitude_rotation(roll, pitch, yaw)
        position = rot @ np.asarray(mount.position_m, float) + np.array([0.0, 0.0, -heave])
        return Pose(position, rot @ np.asarray(mount.rotation, float))

    def poses(self, mount: Pose, t_s):
        """The sonar's world poses at many times: positions (n, 3) in m and rotations (n, 3, 3)
        (columns the sonar axes in world coordinates), for times ``t_s`` of shape (n,)."""
        roll, pitch, yaw, heave = self.attitude(np.asarray(t_s, float).reshape(-1))
        rot = attitude_rotation(roll, pitch, yaw)                              # (n, 3, 3)
        position = rot @ np.asarray(mount.position_m, float)
        position[:, 2] -= heave
        return position, rot @ np.asarray(mount.rotation, float)

    def at_arrival(self, mount: Pose, t_s: float, points_world_m, sound_speed_m_s: float):
        """Where world points are in the sonar frame of the moment their echoes arrive.

        The echo of a point at range r from the sonar (transmitted at ``t_s``) arrives at
        t_s + 2r/c; by then the platform has turned and heaved a little. The stop-and-hop
        approximation (``effects.stop_and_hop``) keeps the transmit pose for the receive leg;
        this gives the receive leg's start instead.

        Parameters
        ----------
        mount : Pose
        t_s : float
            Transmission time (s).
        points_world_m : array_like, shape (n, 3)
        sound_speed_m_s : float

        Returns
        -------
        ndarray, shape (n, 3)
            Sonar-frame positions (m) at each point's arrival time.
        """
        p = np.asarray(points_world_m, float).reshape(-1, 3)
        at_tx = self.pose(mount, t_s)
        r = np.linalg.norm(p - at_tx.position_m, axis=1)
        position, rot = self.poses(mount, t_s + 2.0 * r / sound_speed_m_s)
        return np.einsum("nji,nj->ni", rot, p - position)


def pose_at_time_zero(scene) -> Pose:
    """The sonar's world pose at ping 0 (t = 0): where moving targets given relative to the
    sonar start from."""
    from acoustics.sonar.build import build_sonar
    mount = build_sonar(scene).pose
    if scene.sonar.motion is None:
        return mount
    return PlatformMotion.from_spec(scene.sonar.motion, scene.resolve_path).pose(mount, 0.0)
