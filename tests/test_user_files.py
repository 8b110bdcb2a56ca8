"""Every file a user supplies goes through one gate (processing/base/files.py), and every size
driver feeds the resource estimate (issue 27, classes 1–3).

Each bad case runs the command a user would (``abacus scene check`` / ``simulate`` / ``count``)
and must end with the documented exit status (2 bad input, 3 too large), exactly one line on
stderr naming the file or key and what is accepted, no traceback, nothing left behind, and no
text of a file outside the scene's folder quoted back. Controls show that good motion files,
meshes, grids and noise files still work. The commands run in one child process (the import
once), except those that could hang, which run on their own under a timeout.
"""
from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from processing.base.files import (ALLOW_OUTSIDE_ENV, FileRefused, check_file, line_column,
                                   read_bytes, read_text)

#: what the file outside the scene's folder holds: it must never appear in a message
SECRET = "SECRET-LINE-7f3a"
BASE = ("name: u\npings: {count: 1}\n"
        "processing: {detect: {method: fraction_of_peak, fraction: 0.5}}\n")
GOOD_MOTION = "time_s,roll_deg,pitch_deg,yaw_deg,heave_m\n0,0,0,0,0\n1,2,-1,3,0.5\n2,-2,1,6,-0.5\n"


def motion_scene(file="motion.csv"):
    return BASE + f"sonar: {{motion: {{kind: file, file: '{file}'}}}}\n"


def grid_scene(file):
    return BASE + ("boundaries:\n  - {name: f, role: floor, mesh: {shape: height_grid, "
                   f"file: '{file}', spacing_m: [1, 1], origin_m: [-10, -10]}}}}\n")


def mesh_scene(file):
    return BASE + ("boundaries:\n  - {name: rock, role: obstacle, mesh: {shape: file, "
                   f"file: '{file}', transform: {{translate_m: [0, 3, 25]}}}}}}\n")


def noise_scene(file):
    return BASE.replace("fraction: 0.5}", f"fraction: 0.5, noise: {{source: noise_file, file: '{file}'}}}}")


def _sparse(path: Path, head: bytes, size: int):
    """A file of ``size`` bytes that starts with ``head`` and takes no disk (a hole)."""
    with open(path, "wb") as fh:
        fh.write(head)
    os.truncate(path, size)


def _npy_head(shape, descr="<f8") -> bytes:
    import io
    from numpy.lib import format as npy
    b = io.BytesIO()
    npy.write_array_header_1_0(b, {"descr": descr, "fortran_order": False, "shape": shape})
    return b.getvalue()


# ---------------------------------------------------------------------------- the cases
# name: (files {relative path: text or bytes or callable(folder)}, argv, env, status, words)
# the scene is always s/s.yaml; the folder above it holds outside.csv (the secret)
CASES = {
    # class 1: a bad motion file is user input, one line with file:line(:column)
    "motion: no time_s": ({"s/motion.csv": "roll_deg,pitch_deg\n1,2\n"}, None, {}, 2,
                          ["motion.csv:1", "no time_s", "sonar.motion.file"]),
    "motion: NaN": ({"s/motion.csv": "time_s,roll_deg\n0,1\n1,nan\n"}, None, {}, 2,
                    ["motion.csv:3", "column roll_deg", "col 3", "finite"]),
    "motion: time goes back": ({"s/motion.csv": "time_s,roll_deg\n0,1\n2,1\n1,1\n"}, None, {}, 2,
                               ["motion.csv:4", "increase strictly"]),
    "motion: empty": ({"s/motion.csv": ""}, None, {}, 2, ["motion.csv", "empty", "time_s"]),
    "motion: header only": ({"s/motion.csv": "time_s,roll_deg\n"}, None, {}, 2,
                            ["motion.csv", "no data rows"]),
    "motion: semicolons": ({"s/motion.csv": "time_s;roll_deg\n0;1,5\n"}, None, {}, 2,
                           ["motion.csv:1:7", "semicolons", "commas"]),
    "motion: tabs": ({"s/motion.csv": "time_s\troll_deg\n0\t1\n"}, None, {}, 2,
                     ["motion.csv:1:7", "tabs", "commas"]),
    "motion: ragged row": ({"s/motion.csv": "time_s,roll_deg\n0,1\n1,2,3\n"}, None, {}, 2,
                           ["motion.csv:3:5", "3 values", "2 columns"]),
    "motion: not a number": ({"s/motion.csv": "time_s,roll_deg\n0,abc\n"}, None, {}, 2,
                             ["motion.csv:2", "column roll_deg", "not a number", "degrees"]),
    "motion: binary bytes": ({"s/motion.csv": b"time_s,roll_deg\n0,\x00\x01\x02\n"}, None, {}, 2,
                             ["motion.csv:2:3", "binary"]),
    "motion: not UTF-8": ({"s/motion.csv": b"time_s,roll_deg\n0,\xff\xfe1\n"}, None, {}, 2,
                          ["motion.csv:2:3", "not UTF-8"]),
    "motion: unknown column": ({"s/motion.csv": "time_s,rol_deg\n0,1\n"}, None, {}, 2,
                               ["motion.csv:1:8", "header column 2", "roll_deg"]),
    "motion: a column twice": ({"s/motion.csv": "time_s,roll_deg,roll_deg\n0,1,1\n"}, None, {}, 2,
                               ["header column 3", "second time"]),
    "motion: a folder": ({"s/motion.csv/x": "1"}, None, {}, 2, ["'motion.csv'", "a folder"]),
    "motion: missing": ({}, None, {}, 2, ["'motion.csv'", "not found", "relative to the scene's folder"]),
    "motion: heave 400 m": ({"s/motion.csv": "time_s,heave_m\n0,0\n1,400\n"}, None, {}, 2,
                            ["motion.csv:3", "column heave_m", "400 m is outside ±20 m"]),
    "motion: roll 500°": ({"s/motion.csv": "time_s,roll_deg\n0,500\n"}, None, {}, 2,
                          ["motion.csv:2", "500° is outside ±360°"]),
    "inline: heave 400 m": ({"s/s.yaml": BASE + "sonar: {motion: {kind: series, series: "
                             "{time_s: [0, 1], heave_m: [0, 400]}}}\n"}, None, {}, 2,
                            ["sonar.motion", "400 m is outside ±20 m"]),
    "inline: roll 500°": ({"s/s.yaml": BASE + "sonar: {motion: {kind: series, series: "
                           "{time_s: [0, 1], roll_deg: [0, 500]}}}\n"}, None, {}, 2,
                          ["sonar.motion", "500° is outside ±360°"]),
    "simulate refuses a bad motion file up front": (
        {"s/motion.csv": "time_s,roll_deg\n0,1\n1,nan\n"},
        ["simulate", "s/s.yaml", "-o", "out.nc"], {}, 2, ["motion.csv:3", "finite"]),
    # class 2: motion and noise files obey the rules mesh files follow
    "motion: ../outside.csv": ({"s/s.yaml": motion_scene("../outside.csv")}, None, {}, 2,
                               ["'../outside.csv'", "outside the scene's folder",
                                ALLOW_OUTSIDE_ENV]),
    "motion: a symlink out": ({"s/s.yaml": motion_scene("link.csv"),
                               "s/link.csv": lambda f: (f / "s" / "link.csv").symlink_to(f / "outside.csv")},
                              None, {}, 2, ["'link.csv'", "outside the scene's folder"]),
    "motion: an absolute path outside": ({"s/s.yaml": lambda f: (f / "s" / "s.yaml").write_text(
        motion_scene(str(f / "outside.csv")))}, None, {}, 2, ["outside the scene's folder"]),
    "motion: outside allowed, still never quoted": (
        {"s/s.yaml": lambda f: (f / "s" / "s.yaml").write_text(motion_scene(str(f / "outside.csv")))},
        None, {ALLOW_OUTSIDE_ENV: "1"}, 2, ["outside.csv:1:1", "header column 1"]),
    "motion: a 17-hour 100 Hz log": (
        {"s/motion.csv": lambda f: _sparse(f / "s" / "motion.csv", b"time_s,roll_deg\n", 17 * 3600 * 100 * 28)},
        None, {}, 2, ["'motion.csv'", "171.4 MB", "at most 64.0 MB"]),
    "motion: over a million rows": (
        {"s/motion.csv": lambda f: (f / "s" / "motion.csv").write_text(
            "time_s,roll_deg\n" + "".join(f"{i},0\n" for i in range(1_000_100)))},
        None, {}, 2, ["motion.csv", "at most 1,000,000 rows"]),
    "noise file: /etc/passwd-like, outside": (
        {"s/s.yaml": lambda f: (f / "s" / "s.yaml").write_text(noise_scene(str(f / "outside.csv")))},
        None, {}, 2, ["processing.detect.noise.file", "outside the scene's folder"]),
    "noise file: missing": ({"s/s.yaml": noise_scene("noise.nc")}, None, {}, 2,
                            ["processing.detect.noise.file", "'noise.nc' not found"]),
    "noise file: not a dataset": ({"s/s.yaml": noise_scene("noise.nc"), "s/noise.nc": SECRET + "\n"},
                                  None, {}, 2, ["processing.detect.noise.file", "NetCDF4"]),
    "noise file: a FIFO": ({"s/s.yaml": noise_scene("fifo.nc"),
                            "s/fifo.nc": lambda f: os.mkfifo(f / "s" / "fifo.nc")},
                           None, {}, 2, ["'fifo.nc'", "FIFO", "noise-only dataset"]),
    "mesh: a FIFO": ({"s/s.yaml": mesh_scene("m.obj"), "s/m.obj": lambda f: os.mkfifo(f / "s" / "m.obj")},
                     None, {}, 2, ["boundaries[0].mesh.file", "FIFO"]),
    "grid: a symlink out": ({"s/s.yaml": grid_scene("g.csv"),
                             "s/g.csv": lambda f: (f / "s" / "g.csv").symlink_to(f / "outside.csv")},
                            None, {}, 2, ["boundaries[0].mesh.file", "outside the scene's folder"]),
    "grid: a copy of an outside file in the folder": (
        {"s/s.yaml": grid_scene("g.csv"), "s/g.csv": SECRET + ",1\n2,3\n"}, None, {}, 2,
        ["not a height grid"]),
    "grid: a pickled .npy": ({"s/s.yaml": grid_scene("g.npy"),
                              "s/g.npy": lambda f: np.save(f / "s" / "g.npy", np.array([{"a": 1}], dtype=object),
                                                           allow_pickle=True)},
                             None, {}, 2, ["g.npy is not a height grid", "no array of numbers"]),
    "grid: a .npy header that lies": ({"s/s.yaml": grid_scene("g.npy"),
                                       "s/g.npy": _npy_head((100_000, 100_000)) + b"\0" * 64},
                                      None, {}, 2, ["g.npy is not a height grid", "header's shape (100000, 100000)"]),
    # class 3: every size driver feeds the estimate before anything is allocated
    "plane of 10^5 x 10^5 segments": (
        {"s/s.yaml": BASE + "boundaries:\n  - {name: f, role: floor, mesh: {shape: plane, "
                            "center_m: [0, 0, 30], segments: [100000, 100000]}}\n"},
        None, {}, 3, ["boundaries[0].mesh.segments", "2e+10 faces", "faces fit"]),
    "a school of 10^8 fish": (
        {"s/s.yaml": BASE + "targets:\n  populations:\n    - {kind: school, center_m: [0, 0, 30], "
                            "semi_axes_m: [5, 5, 5], count: 100000000}\n"},
        None, {"ABACUS_MAX_MEMORY_GB": "8"}, 3, ["targets.populations[0].count", "schools", "targets fit"]),
    "a school by density": (
        {"s/s.yaml": BASE + "targets:\n  populations:\n    - {kind: school, center_m: [0, 0, 60], "
                            "semi_axes_m: [50, 50, 50], density_per_m3: 100000}\n"},
        None, {}, 3, ["targets.populations[0].density_per_m3", "per m³ fit"]),
    "a .npy grid whose header holds 5000 x 5000": (
        {"s/s.yaml": grid_scene("g.npy"),
         "s/g.npy": lambda f: _sparse(f / "s" / "g.npy", _npy_head((5000, 5000)),
                                      len(_npy_head((5000, 5000))) + 5000 * 5000 * 8)},
        None, {"ABACUS_MAX_MEMORY_GB": "2"}, 3, ["boundaries[0].mesh.file", "49,980,002 faces"]),
    "a binary STL of 5 million faces": (
        {"s/s.yaml": mesh_scene("m.stl"),
         "s/m.stl": lambda f: _sparse(f / "s" / "m.stl", b"\0" * 80 + struct.pack("<I", 5_000_000),
                                      84 + 50 * 5_000_000)},
        None, {"ABACUS_MAX_MEMORY_GB": "0.6"}, 3, ["boundaries[0].mesh.file", "5,000,000 faces"]),
    "a PLY header that lies about its faces": (
        {"s/s.yaml": mesh_scene("m.ply"),
         "s/m.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                    b"property float y\nproperty float z\nelement face 1000000000\n"
                    b"property list uchar int vertex_indices\nend_header\n" + b"\0" * 100},
        None, {}, 2, ["boundaries[0].mesh", "cannot read mesh file", "PLY"]),
    # controls: good files still work
    "control: a good motion file": ({"s/motion.csv": GOOD_MOTION}, None, {}, 0, ["motion file of 3 row(s)"]),
    "control: a motion file with a BOM and CRLF": (
        {"s/motion.csv": "\ufefftime_s,roll_deg\r\n0,1\r\n\r\n1,2\r\n".encode("utf-8")}, None, {}, 0,
        ["motion file of 2 row(s)"]),
    "control: simulate with a good motion file": (
        {"s/motion.csv": GOOD_MOTION}, ["simulate", "s/s.yaml", "-o", "out.nc"], {}, 0, ["wrote out.nc"]),
    "control: a good OBJ and a good .npy grid": (
        {"s/s.yaml": BASE + "boundaries:\n  - {name: rock, role: obstacle, mesh: {shape: file, file: m.obj, "
                            "transform: {translate_m: [0, 3, 25]}}}\n  - {name: f, role: floor, mesh: "
                            "{shape: height_grid, file: g.npy, spacing_m: [1, 1], origin_m: [-10, -10]}}\n",
         "s/m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
         "s/g.npy": lambda f: np.save(f / "s" / "g.npy", np.full((20, 20), 40.0))},
        None, {}, 0, ["2 mesh(es)"]),
}
#: commands that must not hang: each in a process of its own, under a timeout
OWN_PROCESS = {"noise file: a FIFO", "mesh: a FIFO", "motion: a 17-hour 100 Hz log"}


def _prepare(root: Path, name: str):
    files, argv, env, status, words = CASES[name]
    folder = root / f"case{sorted(CASES).index(name):02d}"
    (folder / "s").mkdir(parents=True)
    (folder / "outside.csv").write_text(SECRET + "\n1,2\n")
    files = {"s/s.yaml": motion_scene(), **files}
    for rel, content in files.items():
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if callable(content):
            content(folder)
        elif isinstance(content, bytes):
            p.write_bytes(content)
        else:
            p.write_text(content)
    return folder, argv or ["scene", "check", "s/s.yaml"], env


_RUNNER = r"""
import contextlib, io, json, os, sys
from abacus.cli import main
out = []
for folder, argv, env in json.loads(sys.stdin.read()):
    os.chdir(folder)
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    err, std = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
    out.append({"code": code, "stderr": err.getvalue(), "stdout": std.getvalue()})
print(json.dumps(out))
"""


def _listing(folder: Path):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    root = tmp_path_factory.mktemp("user-files")
    prepared = {name: _prepare(root, name) for name in CASES}
    before = {name: _listing(f) for name, (f, _, _) in prepared.items()}
    batch = [n for n in CASES if n not in OWN_PROCESS]
    env = {**os.environ}
    env.pop(ALLOW_OUTSIDE_ENV, None)
    env.pop("ABACUS_MAX_MEMORY_GB", None)
    done = subprocess.run([sys.executable, "-c", _RUNNER], capture_output=True, text=True, env=env,
                          input=json.dumps([[str(prepared[n][0]), prepared[n][1], prepared[n][2]]
                                            for n in batch]), timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    out = dict(zip(batch, json.loads(done.stdout.strip().splitlines()[-1])))
    for name in OWN_PROCESS:
        folder, argv, extra = prepared[name]
        r = subprocess.run([sys.executable, "-m", "abacus", *argv], cwd=folder, capture_output=True,
                           text=True, env={**env, **extra}, timeout=60)
        out[name] = {"code": r.returncode, "stderr": r.stderr, "stdout": r.stdout}
    for name, (folder, _, _) in prepared.items():
        out[name]["left"] = sorted(set(_listing(folder)) - set(before[name]))
    return out


@pytest.mark.parametrize("name", sorted(CASES))
def test_each_case_ends_in_one_line_and_its_status(results, name):
    r = results[name]
    status, words = CASES[name][3], CASES[name][4]
    assert r["code"] == status, (name, r["stderr"][-600:])
    assert "Traceback" not in r["stderr"] and "internal error" not in r["stderr"]
    assert SECRET not in r["stderr"] + r["stdout"]         # nothing of another file quoted
    errors = [line for line in r["stderr"].splitlines() if not line.startswith("warning:")]
    if status == 0:
        assert errors == [], r["stderr"]
        assert all(w in r["stdout"] + r["stderr"] for w in words), r["stdout"]
        expected = ["out.nc"] if "simulate" in name else []
        assert r["left"] == expected
        return
    assert len(errors) == 1 and errors[0].startswith("error: "), r["stderr"]
    missing = [w for w in words if w not in errors[0]]
    assert missing == [], errors[0]
    assert r["left"] == []                                  # nothing left behind


# ---------------------------------------------------------------------- the gate itself
def test_the_gate_refuses_what_is_not_a_regular_file_inside_the_folder(tmp_path, monkeypatch):
    monkeypatch.delenv(ALLOW_OUTSIDE_ENV, raising=False)
    home = tmp_path / "scene"
    home.mkdir()
    (tmp_path / "out.txt").write_text(SECRET)
    (home / "in.txt").write_text("ok\n")
    (home / "up").symlink_to(tmp_path / "out.txt")
    (home / "loop").symlink_to(home / "loop")
    os.mkfifo(home / "fifo")
    gate = dict(folder=home, max_bytes=100, what="thing file", key="a.key", where="s.yaml:3")
    assert check_file("in.txt", **gate).size == 3
    for name, words in [("../out.txt", "outside the scene's folder"), ("up", "outside"),
                        (str(tmp_path / "out.txt"), "outside"), ("fifo", "FIFO"), (".", "a folder"),
                        ("none", "not found"), ("", "give a file name"), ("/dev/zero", "outside")]:
        with pytest.raises(FileRefused) as e:
            read_bytes(name, **gate)
        msg = str(e.value)
        assert msg.startswith("s.yaml:3: a.key: ") and words in msg and SECRET not in msg
        assert "\n" not in msg
    with pytest.raises(FileRefused, match="loop|outside|cannot"):
        check_file("loop", **gate)
    monkeypatch.setenv(ALLOW_OUTSIDE_ENV, "1")
    assert read_bytes("up", **gate)[1] == SECRET.encode()
    with pytest.raises(FileRefused, match="is a device"):
        read_bytes("/dev/zero", **gate)
    with pytest.raises(FileRefused, match="at most 100 bytes"):
        (home / "big.txt").write_text("x" * 101)
        read_bytes("big.txt", **gate)
    # a path named on the command line has no folder
    monkeypatch.delenv(ALLOW_OUTSIDE_ENV)
    assert check_file(tmp_path / "out.txt", max_bytes=100).size == len(SECRET)


def test_a_fifo_never_hangs_the_gate(tmp_path):
    """``open`` of a FIFO waits for a writer: the gate must refuse it from stat, in a child
    that a timeout would catch if it ever blocked."""
    os.mkfifo(tmp_path / "f")
    code = ("from processing.base.files import read_text, FileRefused\n"
            f"try:\n    read_text({str(tmp_path / 'f')!r}, max_bytes=10)\n"
            "except FileRefused as e:\n    print('refused', e)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    assert r.stdout.startswith("refused") and "FIFO" in r.stdout


@pytest.mark.parametrize("data, text", [
    (b"\xef\xbb\xbfa,b\n", "a,b\n"),
    ("a,b\n".encode("utf-16"), "a,b\n"),
    ("a,é\n".encode("utf-32"), "a,é\n"),
    (b"a,b\r\n", "a,b\r\n"),
])
def test_text_honours_a_byte_order_mark(tmp_path, data, text):
    (tmp_path / "t.csv").write_bytes(data)
    assert read_text(tmp_path / "t.csv", max_bytes=100)[1] == text


def test_text_errors_name_line_and_column_not_content(tmp_path):
    (tmp_path / "t.csv").write_bytes(b"ok\nab\x00\n")
    with pytest.raises(FileRefused, match=r"t\.csv:2:3: binary data"):
        read_text(tmp_path / "t.csv", max_bytes=100)
    (tmp_path / "t.csv").write_bytes(b"ok\nabc\xff\n")
    with pytest.raises(FileRefused, match=r"t\.csv:2:4: not UTF-8 text"):
        read_text(tmp_path / "t.csv", max_bytes=100)
    assert line_column("ab\ncd", 4) == (2, 2) and line_column(b"ab", 0) == (1, 1)


# --------------------------------------------------------- motion: one rule, two forms
def test_a_motion_file_and_the_inline_series_share_their_bounds(tmp_path):
    from acoustics.scene import SceneError, scene_from_text
    from acoustics.sonar.platform import MOTION_BOUNDS, MotionFileError, read_motion_csv
    for column, (bound, _) in MOTION_BOUNDS.items():
        ok, bad = bound, bound * 1.01
        (tmp_path / "m.csv").write_text(f"time_s,{column}\n0,{ok}\n1,{-ok}\n")
        assert read_motion_csv("m.csv", folder=tmp_path)[column].tolist() == [ok, -ok]
        (tmp_path / "m.csv").write_text(f"time_s,{column}\n0,{bad}\n")
        with pytest.raises(MotionFileError, match="is outside"):
            read_motion_csv("m.csv", folder=tmp_path)
        scene_from_text(f"name: m\nsonar: {{motion: {{kind: series, series: {{time_s: [0], {column}: [{-ok}]}}}}}}\n")
        with pytest.raises(SceneError, match="is outside"):
            scene_from_text(f"name: m\nsonar: {{motion: {{kind: series, series: {{time_s: [0], "
                            f"{column}: [{bad}]}}}}}}\n")


def test_a_scene_with_a_bad_motion_file_fails_at_load_as_a_scene_error(tmp_path):
    from acoustics.scene import SceneError, load_scene
    from acoustics.sonar.platform import MotionFileError
    (tmp_path / "m.csv").write_text("time_s,roll_deg\n0,1\n0,2\n")
    (tmp_path / "s.yaml").write_text(BASE + "sonar: {motion: {kind: file, file: m.csv}}\n")
    with pytest.raises(SceneError) as e:
        load_scene(tmp_path / "s.yaml")
    assert isinstance(e.value, MotionFileError)
    assert f"{tmp_path / 's.yaml'}:4: sonar.motion.file: " in str(e.value) and "m.csv:3" in str(e.value)


def test_a_motion_file_is_read_once_for_the_load_and_the_run(tmp_path):
    from acoustics.scene import load_scene
    from acoustics.simulation.setup import make_setup
    from acoustics.sonar import platform
    (tmp_path / "m.csv").write_text(GOOD_MOTION)
    (tmp_path / "s.yaml").write_text(BASE + "sonar: {motion: {kind: file, file: m.csv}}\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(tmp_path / "s.yaml")
        calls = []
        real = platform._parse_motion
        try:
            platform._parse_motion = lambda *a: calls.append(1) or real(*a)
            setup = make_setup(scene)
        finally:
            platform._parse_motion = real
    assert calls == []     # the load's read is kept (same path, size and time)
    roll, pitch, yaw, heave = setup.platform.attitude(0.5)
    assert np.degrees(roll) == pytest.approx(1.0) and heave == pytest.approx(0.25)


# ------------------------------------------------------------------ the estimate's drivers
def test_the_estimate_counts_motion_rows_schools_and_file_faces(tmp_path):
    from acoustics.scene import load_scene
    from acoustics.simulation.budget import estimate_scene, mesh_faces
    import trimesh
    box = trimesh.creation.box(extents=[1, 1, 1])
    for suffix in ("stl", "ply", "off", "obj"):
        box.export(tmp_path / f"m.{suffix}")
    np.save(tmp_path / "g.npy", np.zeros((30, 40)))
    (tmp_path / "m.csv").write_text("time_s,roll_deg\n" + "".join(f"{i},0\n" for i in range(5000)))
    (tmp_path / "s.yaml").write_text(
        BASE + "sonar: {motion: {kind: file, file: m.csv}}\n"
        "targets:\n  populations:\n    - {kind: school, center_m: [0, 0, 30], semi_axes_m: [3, 3, 3], count: 1000}\n"
        "boundaries:\n" + "".join(f"  - {{name: b{s}, role: obstacle, mesh: {{shape: file, file: m.{s}}}}}\n"
                                  for s in ("stl", "ply", "off", "obj"))
        + "  - {name: f, role: floor, mesh: {shape: height_grid, file: g.npy, spacing_m: [1, 1]}}\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(tmp_path / "s.yaml")
    faces = [mesh_faces(b, scene.resolve_path) for b in scene.boundaries]
    assert faces[0] == 12 and faces[1] == 12 and faces[2] >= 12       # headers: exact
    assert faces[3] >= 12                                              # OBJ: a bound by size
    assert faces[4] == 2 * 29 * 39                                     # .npy: its header's shape
    est = estimate_scene(scene)
    terms = dict(est.terms)
    assert terms["motion"] >= 5000 * 40 and terms["schools"] >= 1000 * 800
    assert {d.key for d in est.drivers} >= {"sonar.motion.file", "targets.populations[0].count",
                                           "boundaries[4].mesh.file", "pings.count (or --pings)"}


def test_a_refusal_names_the_largest_driver_and_what_fits():
    from processing.base.resources import Driver, Estimate, ResourceError, check_resources
    est = Estimate(4e9, 0, [("meshes", 3e9), ("runtime", 1e9)], keys="everything",
                   drivers=[Driver("boundaries[0].mesh.segments", 3e7, "faces", 3e9),
                            Driver("pings.count (or --pings)", 1, "pings", 1e6)])
    with pytest.raises(ResourceError) as e:
        check_resources(est, what="scene 'x'", max_memory_gb=2)
    msg = str(e.value)
    assert "most of it is boundaries[0].mesh.segments (30,000,000 faces" in msg
    # 2 GiB less the 1 GB that stays: ≈ 1.15 GB of faces at 100 bytes each
    assert "about 11,474,836 faces fit" in msg and "\n" not in msg


def test_the_noise_file_of_processing_goes_through_the_gate(tmp_path):
    """``count --settings``: the noise file is relative to the working directory and must lie
    there; the dataset's own settings (``abacus run``): relative to its scene's folder. A good
    one is read; one outside is refused in one line, its contents never quoted."""
    (tmp_path / "outside.csv").write_text(SECRET + "\n")
    work = tmp_path / "work"
    (work / "scene").mkdir(parents=True)
    (work / "bad.yaml").write_text(f"detect: {{noise: {{source: noise_file, file: '{tmp_path / 'outside.csv'}'}}}}\n")
    (work / "good.yaml").write_text("detect: {noise: {source: noise_file, file: cwd_noise.nc}}\n")
    (work / "scene" / "s.yaml").write_text(noise_scene("noise.nc"))
    argv = [["simulate", "noise_only", "-o", "cwd_noise.nc", "--pings", "1"],
            ["simulate", "noise_only", "-o", "scene/noise.nc", "--pings", "1"],
            ["simulate", "two_targets", "-o", "d.nc"],
            ["count", "d.nc", "--settings", "bad.yaml"],
            ["count", "d.nc", "--settings", "good.yaml"],
            ["run", "scene/s.yaml", "-o", "runs", "--no-plots"]]
    env = {k: v for k, v in os.environ.items() if k != ALLOW_OUTSIDE_ENV}
    done = subprocess.run([sys.executable, "-c", _RUNNER], capture_output=True, text=True, env=env,
                          input=json.dumps([[str(work), a, {}] for a in argv]), timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert [r["code"] for r in out[:3]] == [0, 0, 0], [r["stderr"] for r in out[:3]]
    bad = out[3]
    errors = [line for line in bad["stderr"].splitlines() if not line.startswith("warning:")]
    assert bad["code"] == 2 and len(errors) == 1 and SECRET not in bad["stderr"]
    assert "detect.noise.file" in errors[0] and "outside the working directory" in errors[0]
    assert out[4]["code"] == 0, out[4]["stderr"]
    assert out[5]["code"] == 0, out[5]["stderr"]
