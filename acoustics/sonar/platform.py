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

import numpy as np

from acoustics.frames import Pose
from processing.base.config import ConfigError

__all__ = ["attitude_rotation", "PlatformMotion", "read_motion_csv", "MotionFileError",
           "MOTION_BOUNDS", "MOTION_COLUMNS", "motion_value_problem", "motion_time_problem",
           "MAX_MOTION_FILE_BYTES", "MAX_MOTION_ROWS"]

#: a motion file's most bytes (checked before it is read) and rows (before it is parsed): a
#: million rows are 2.8 h at 100 Hz (28 h at 10 Hz); a longer log is thinned out or cut to the run
MAX_MOTION_FILE_BYTES = 64_000_000
MAX_MOTION_ROWS = 1_000_000


class MotionFileError(ConfigError):
    """A motion CSV that cannot be used (the message names the file, line and column, the key
    and what is accepted; never the text found there). A scene's load raises it as a
    :class:`~acoustics.scene.SceneError` too."""


#: the largest |value| of each column of a motion series (degrees; metres for heave): the same
#: bound whether the series is written inline (``series``) or read from a file (``file``) —
#: angles within a turn either way, heave within the 20 m of the largest swell model
#: (:class:`~acoustics.scene.motion_spec.SwellSpec`'s ``heave_amplitude_m``)
MOTION_BOUNDS = {"roll_deg": (360.0, "°"), "pitch_deg": (360.0, "°"), "yaw_deg": (360.0, "°"),
                 "heave_m": (20.0, " m")}
#: the columns of a motion series, time first
MOTION_COLUMNS = ("time_s", *MOTION_BOUNDS)


def motion_value_problem(column: str, value: float) -> str | None:
    """What is wrong with one value of a motion series' column, or None (the rule both forms of
    a series — inline and file — follow)."""
    if not math.isfinite(value):
        return "not a finite number"
    if column in MOTION_BOUNDS:
        bound, unit = MOTION_BOUNDS[column]
        if abs(value) > bound:
            return f"{value:g}{unit} is outside ±{bound:g}{unit}"
    return None


def motion_time_problem(time_s) -> tuple[int, str] | None:
    """(index, what is wrong) of the first time of a series that does not follow the one
    before strictly, or None; (0, ...) for an empty series."""
    if len(time_s) < 1:
        return 0, "time_s needs at least one time"
    for i in range(1, len(time_s)):
        if not time_s[i] > time_s[i - 1]:
            return i, (f"time_s must increase strictly: {time_s[i]:g} s follows "
                       f"{time_s[i - 1]:g} s")
    return None


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


_ACCEPTED = ("a header naming time_s and any of roll_deg, pitch_deg, yaw_deg, heave_m, then one "
             "row of numbers per time, separated by commas")
_CACHE: dict = {}


def read_motion_csv(path, *, folder=None, key: str = "sonar.motion.file",
                    where: str | None = None) -> dict:
    """Columns of a motion CSV, as float arrays, read through the file gate.

    The file (:class:`~acoustics.scene.motion_spec.PlatformMotionSpec` describes it) is UTF-8
    text (a byte-order mark allowed) of at most :data:`MAX_MOTION_FILE_BYTES` and
    :data:`MAX_MOTION_ROWS` rows: a header naming ``time_s`` and any of ``roll_deg``,
    ``pitch_deg``, ``yaw_deg``, ``heave_m`` once each, then one row of numbers per time,
    separated by commas (``;`` or tabs are refused: commas are expected); blank lines are
    skipped. Times increase strictly; values stay within
    :data:`MOTION_BOUNDS`, as the inline series' do. A file read
    once is kept (keyed by its path, size and modification time), as the scene's load, its
    checks and the simulation all read it.

    Parameters
    ----------
    path : str or Path
        As the scene writes it (relative to ``folder``), or a path.
    folder : str or Path, optional
        The scene file's folder, where the file must lie (:func:`processing.base.files.check_file`);
        None: the path is taken as it is (a caller that named the file itself).
    key, where : str
        The scene key and the place naming it (``"scene.yaml:12"``), for messages.

    Returns
    -------
    dict of str to ndarray
        ``time_s`` and the columns the header names, each shape (T,), read-only.

    Raises
    ------
    MotionFileError
        Every problem, as one line: file, line and column, key, what is accepted.
    """
    import os

    from processing.base.files import FileRefused, check_file, read_text
    gate = dict(folder=folder, key=key, where=where, what="motion file",
                accepts="a CSV file of motion samples (" + _ACCEPTED + ")")
    try:
        f = check_file(path, max_bytes=MAX_MOTION_FILE_BYTES, **gate)
        st = os.stat(f.path)
        cache_key = (str(f.path.resolve()), st.st_size, st.st_mtime_ns, st.st_ino)
        if cache_key in _CACHE:
            return dict(_CACHE[cache_key])
        f, text = read_text(path, max_bytes=MAX_MOTION_FILE_BYTES, **gate)
    except FileRefused as exc:
        raise MotionFileError(str(exc)) from None
    try:
        out = _parse_motion(text, f)
    except FileRefused as exc:
        raise MotionFileError(str(exc)) from None
    for v in out.values():
        v.flags.writeable = False
    if len(_CACHE) >= 4:
        _CACHE.clear()
    _CACHE[cache_key] = out
    return dict(out)


def _parse_motion(text: str, f) -> dict:
    """The columns of a motion file's text; a FileRefused naming line and column otherwise."""
    import io

    text = text.replace("\r\n", "\n").replace("\r", "\n")
    n_lines = text.count("\n") + 1
    if n_lines > MAX_MOTION_ROWS + 1:
        raise f.refuse(f"{f.path}: {n_lines:,} lines; a motion file holds at most "
                       f"{MAX_MOTION_ROWS:,} rows (2.8 h at 100 Hz): thin it out (10 Hz is plenty "
                       f"for a platform's motion) or cut it to the run")
    head_at = 0
    lines = io.StringIO(text)
    header = None
    for ln, line in enumerate(lines, start=1):
        if line.strip():
            header, head_at = line.rstrip("\n"), ln
            break
    if header is None:
        raise f.refuse(f"{f.path}: empty; expected {_ACCEPTED}")
    _separators(header, f, head_at)
    names, starts = _fields(header)
    for j, (h, c) in enumerate(zip(names, starts), start=1):
        if h not in MOTION_COLUMNS:
            what = "is empty" if not h else f"is not one of {', '.join(MOTION_COLUMNS)}"
            raise f.refuse(f"{f.path}:{head_at}:{c}: header column {j} {what}; expected {_ACCEPTED}")
        if names.index(h) != j - 1:
            raise f.refuse(f"{f.path}:{head_at}:{c}: header column {j} names {h} a second time; "
                           f"each column once")
    if "time_s" not in names:
        raise f.refuse(f"{f.path}:{head_at}: the header names no time_s column; expected {_ACCEPTED}")
    rest = lines.read()   # the data follow the header's line
    values = _fast_values(rest, len(names))
    if values is None or not _valid(values, names):
        values = _located_values(rest, names, f, head_at)
    if values.shape[0] == 0:
        raise f.refuse(f"{f.path}: a header but no data rows; expected {_ACCEPTED}")
    return {h: np.ascontiguousarray(values[:, j]) for j, h in enumerate(names)}


def _separators(line: str, f, ln: int):
    for sep, name in ((";", "semicolons"), ("\t", "tabs")):
        if sep in line:
            raise f.refuse(f"{f.path}:{ln}:{line.index(sep) + 1}: values separated by {name}; a "
                           f"motion file separates them by commas (and writes decimals with a "
                           f"point): {_ACCEPTED}")


def _fields(line: str):
    """Stripped fields of a comma-separated line and the column (from 1) where each starts."""
    parts = line.split(",")
    starts, at = [], 1
    for p in parts:
        starts.append(at + len(p) - len(p.lstrip()))
        at += len(p) + 1
    return [p.strip() for p in parts], starts


def _fast_values(rest: str, n: int):
    """The data rows parsed by a compiled reader (pandas' C parser, else numpy's; little memory),
    or None: the slow reader then finds the problem and names its line and column."""
    import csv
    import io
    import warnings
    if not rest.strip():
        return np.zeros((0, n))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                import pandas as pd
            except ImportError:   # pragma: no cover - pandas comes with xarray
                v = np.loadtxt(io.StringIO(rest), delimiter=",", dtype=float, ndmin=2, comments=None)
            else:
                v = pd.read_csv(io.StringIO(rest), header=None, dtype=float, engine="c",
                                quoting=csv.QUOTE_NONE, skip_blank_lines=True).to_numpy(float)
    except Exception:   # any refusal of the fast reader: the slow one says where and why
        return None
    return v if v.ndim == 2 and v.shape[1] == n else None


def _valid(values, names) -> bool:
    if not np.all(np.isfinite(values)):
        return False
    for j, h in enumerate(names):
        if h in MOTION_BOUNDS and np.any(np.abs(values[:, j]) > MOTION_BOUNDS[h][0]):
            return False
    t = values[:, names.index("time_s")]
    return bool(np.all(np.diff(t) > 0))


def _located_values(rest: str, names, f, head_at: int):
    """The data rows read one by one, the first problem named with its line and column."""
    import io
    from array import array

    cols = [array("d") for _ in names]
    it = names.index("time_s")
    previous = None
    for ln, line in enumerate(io.StringIO(rest), start=head_at + 1):
        line = line.rstrip("\n")
        if not line.strip():
            continue
        _separators(line, f, ln)
        fields, starts = _fields(line)
        if len(fields) != len(names):
            col = starts[len(names)] if len(fields) > len(names) else len(line) + 1
            raise f.refuse(f"{f.path}:{ln}:{col}: {len(fields)} values for the header's "
                           f"{len(names)} columns; every row holds one value per column, "
                           f"separated by commas")
        for j, (h, s, c) in enumerate(zip(names, fields, starts)):
            where = f"{f.path}:{ln}: column {h} (col {c})"
            if not s:
                raise f.refuse(f"{where}: empty; give a number")
            try:
                v = float(s)
            except ValueError:
                raise f.refuse(f"{where}: not a number; give {_unit(h)}") from None
            bad = motion_value_problem(h, v)
            if bad is not None:
                raise f.refuse(f"{where}: {bad}; give {_unit(h)}")
            if j == it:
                if previous is not None and not v > previous:
                    raise f.refuse(f"{where}: time_s must increase strictly ({v:g} s follows "
                                   f"{previous:g} s)")
                previous = v
            cols[j].append(v)
    return np.column_stack([np.frombuffer(c, float) if len(c) else np.zeros(0) for c in cols]) \
        if cols else np.zeros((0, 0))


def _unit(column: str) -> str:
    """What a column accepts, for messages (the bounds of the inline series)."""
    if column not in MOTION_BOUNDS:
        return "a finite time in seconds"
    bound, unit = MOTION_BOUNDS[column]
    return (f"degrees within ±{bound:g}" if unit == "°" else
            f"metres within ±{bound:g} (positive up)")


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
        """From a scene's ``sonar.motion``; ``resolve`` turns a path in the scene into a file
        (:meth:`~acoustics.scene.schema.Scene.resolve_path`).

        Raises
        ------
        MotionFileError
            A motion file the gate or the reader refuses (:func:`read_motion_csv`).
        """
        z = np.zeros(1)
        if spec.kind == "swell":
            return cls(z, z, z, z, z, spec.swell)
        if spec.kind == "series":
            s = spec.series
            cols = {"time_s": s.time_s, "roll_deg": s.roll_deg, "pitch_deg": s.pitch_deg,
                    "yaw_deg": s.yaw_deg, "heave_m": s.heave_m}
        else:
            # the scene's folder (resolve(".")): the file must lie in it, as at the scene's load
            cols = read_motion_csv(spec.file, folder=resolve("."))
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
