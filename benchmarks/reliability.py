"""Reliability probes: bad inputs, bad options, interrupts and full disks against the `abacus`
command line, each in a fresh folder, classified clean or not. Regenerates docs/reliability.md.

    python benchmarks/reliability.py              # every probe (a few minutes on 2 cores)
    python benchmarks/reliability.py --only paths yaml_bombs
    python benchmarks/reliability.py --list

A probe is *clean* when the command ends as its class expects — a refusal (exit status ≠ 0, or
the documented status) whose stderr is at most 3 lines, holds no traceback and echoes no content
of a file the user did not write, leaving nothing behind in its folder but the inputs (no output,
no temporary) and nothing outside it; or, for the *controls*, a success — so the probes cannot pass
by refusing everything. Interrupts must end within 5 s of the signal; a killed run must leave a
state the next run completes from.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))      # run as a script from any folder, installed or not
ABACUS = [sys.executable, "-m", "abacus"]
SECRET = "root:x:0:0"          # a line of /etc/passwd: must never appear in a message

#: a small, fast scene every probe starts from (1 ping, 1024 samples, two targets)
BASE = """\
name: probe
sampling: {samples: 1024, time_offset_s: 0.017}
processing:
  image: {range_m: [13.0, 20.0], n_beams: 16, interpolation: 2}
  detect: {method: fraction_of_peak, fraction: 0.2}
targets:
  points:
    - {range_m: 17.0, azimuth_deg: 1.0, elevation_deg: 0.1}
    - {range_m: 19.0, azimuth_deg: -2.0, elevation_deg: -0.1}
"""


@dataclass
class Probe:
    cls: str
    name: str
    argv: list
    files: dict = field(default_factory=dict)     # relative path -> str | bytes | callable(path)
    expect: str = "refuse"                        # "refuse" | "ok" | "any" (a correct result or a refusal)
    status: int | None = None                     # the exit status it must end with, if fixed
    timeout: float = 60.0
    env: dict = field(default_factory=dict)
    limits: dict = field(default_factory=dict)    # resource name -> soft/hard limit
    interrupt: tuple | None = None                # (signal, seconds after start)
    then: list | None = None                      # a command that must succeed afterwards
    keep: tuple = ()                              # outputs a refusal may leave (documented)
    setup: object = None                          # callable(folder) run before the probe
    tmpfs_mb: float | None = None                 # run in a size-limited tmpfs (a full disk)
    readonly: bool = False                        # ... mounted read-only
    says: tuple = ()                              # words the refusal must contain (file, key, option)
    check: object = None                          # callable(folder, stdout) -> problem or None (controls)


@dataclass
class Result:
    probe: Probe
    verdict: str
    reason: str = ""
    stderr: str = ""
    seconds: float = 0.0


# ------------------------------------------------------------------ the probes
def _merged(base, extra):
    """``extra`` over ``base``: mappings merged key by key, anything else replaced."""
    if isinstance(base, dict) and isinstance(extra, dict):
        out = dict(base)
        for k, v in extra.items():
            out[k] = _merged(base[k], v) if k in base else v
        return out
    return extra


def scene(extra: str = "", base: str = BASE) -> str:
    """The base scene with ``extra`` (YAML) merged into it: a section the base has already
    (``sampling``, ``targets``, ``processing``) is merged key by key — appending the text would
    write the key twice, and the probe would be refused for that instead of what it names.
    Text that is not a YAML mapping is appended as it is (probes of malformed YAML)."""
    import re

    import yaml
    extra = textwrap.dedent(extra)
    shared = set(re.findall(r"^(\w+):", base, re.M)) & set(re.findall(r"^(\w+):", extra, re.M))
    if not shared:     # nothing written twice: the text as the probe wrote it (YAML 1.2 numbers)
        return base + extra
    try:
        more = yaml.safe_load(extra) if extra.strip() else {}
        data = yaml.safe_load(base)
    except yaml.YAMLError:
        return base + extra
    if not isinstance(more, dict) or not isinstance(data, dict):
        return base + extra
    return yaml.safe_dump(_merged(data, more), sort_keys=False)


def _dataset(kind: str):
    """A writer of a (possibly damaged) dataset, made from a good 1-ping simulation: a copy of
    the file :func:`prepare` made for ``kind`` in the main thread (HDF5 and xarray's file cache
    are not safe across the probes' threads: making them there crashed the harness)."""
    def make(path: Path):
        shutil.copyfile(_dataset_file(kind), path)
    make.kind = kind
    return make


def _dataset_file(kind: str) -> Path:
    return CACHE / f"dataset-{kind}.nc"


def _make_dataset(kind: str, path: Path):
    if True:
        import numpy as np
        import xarray as xr

        from processing.base.dataset import ELEMENT_GROUP
        good = CACHE / "good.nc"
        with xr.open_datatree(good) as opened:    # closed here, not by a collection in a thread
            tree = opened.load().copy()
        if kind == "truncated":
            path.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
            return
        if kind == "empty":
            path.write_bytes(b"")
            return
        if kind == "text":
            path.write_text("this is not a dataset\n" * 20)
            return
        if kind == "hdf5_garbage":
            path.write_bytes(b"\x89HDF\r\n\x1a\n" + os.urandom(4096))
            return
        eg = ELEMENT_GROUP
        if kind == "no_sonar":
            tree = xr.DataTree.from_dict({k: v.ds for k, v in tree.subtree_with_keys if k != "Sonar"}
                                         if hasattr(tree, "subtree_with_keys") else
                                         {n.path: n.ds for n in tree.subtree if n.path != "/Sonar"})
        elif kind == "no_samples":
            ds = tree[eg].to_dataset(inherit=False).drop_vars(["backscatter_r", "backscatter_i"])
            tree[eg] = xr.DataTree(ds)
        elif kind == "no_element_group":
            tree = xr.DataTree.from_dict({n.path: n.ds for n in tree.subtree
                                          if not n.path.startswith(f"/{eg}")})
        elif kind == "nan_samples":
            ds = tree[eg].to_dataset(inherit=False).copy(deep=True)
            ds["backscatter_r"].values[0, 0, 5, 0] = np.nan
            tree[eg] = xr.DataTree(ds)
        elif kind == "no_imaginary_part":
            ds = tree[eg].to_dataset(inherit=False).drop_vars("backscatter_i")
            tree[eg] = xr.DataTree(ds)
        elif kind == "bad_mode":
            ds = tree[eg].to_dataset(inherit=False).copy()
            ds.attrs["mode"] = "sideways"
            tree[eg] = xr.DataTree(ds)
        elif kind == "zero_interval":
            ds = tree[eg].to_dataset(inherit=False).copy()
            ds["sample_interval"] = ds["sample_interval"] * 0.0
            tree[eg] = xr.DataTree(ds)
        elif kind == "zero_replica":
            ds = tree["Sonar"].to_dataset(inherit=False).copy()
            ds["replica_r"] = ds["replica_r"] * 0
            ds["replica_i"] = ds["replica_i"] * 0
            tree["Sonar"].dataset = ds
        elif kind == "wrong_dims":
            ds = tree[eg].to_dataset(inherit=False).copy()
            ds["backscatter_r"] = ds["backscatter_r"].isel(ping_time=0)
            ds["backscatter_i"] = ds["backscatter_i"].isel(ping_time=0)
            tree[eg] = xr.DataTree(ds)
        elif kind == "no_sound_speed":
            ds = tree["Environment"].ds.drop_vars("sound_speed_indicative")
            tree["Environment"] = xr.DataTree(ds)
        elif kind == "only_subarray_a":
            ds = tree[eg].to_dataset(inherit=False)
            keep = np.flatnonzero(ds["element_subarray"].values.astype(str) == "A")
            tree[eg] = xr.DataTree(ds.isel(beam=keep))
        elif kind == "bad_provenance":
            ds = tree["Provenance"].ds.copy()
            ds.attrs["scene_text"] = "a: &x [1]\nb: *x\n"
            tree["Provenance"] = xr.DataTree(ds)
        elif kind == "good":
            pass
        else:  # pragma: no cover
            raise ValueError(kind)
        tree.to_netcdf(path)


def probes() -> list[Probe]:
    P = []

    def add(cls, name, argv, **kw):
        P.append(Probe(cls, name, list(argv), **kw))

    # --- controls: what must work, so that refusing everything cannot pass
    add("controls", "scene check", ["scene", "check", "s.yaml"], files={"s.yaml": BASE}, expect="ok")
    add("controls", "run, no plots", ["run", "s.yaml", "-o", "out", "--no-plots"], files={"s.yaml": BASE},
        expect="ok", keep=("out",))
    add("controls", "simulate then count", ["simulate", "s.yaml", "-o", "s.nc"], files={"s.yaml": BASE},
        expect="ok", keep=("s.nc",), then=["count", "s.nc", "--json"])
    add("controls", "image with plots", ["image", "d.nc", "--plots", "figs"], files={"d.nc": _dataset("good")},
        expect="ok", keep=("figs",))
    add("controls", "experiment, 2 pings", ["experiment", "s.yaml", "--pings", "2", "--workers", "0", "-o", "exp"],
        files={"s.yaml": BASE}, expect="ok", keep=("exp",), timeout=120)
    add("controls", "dataset without subarray B (warned, imaged as normal)", ["count", "d.nc"],
        files={"d.nc": _dataset("only_subarray_a")}, expect="ok")
    add("controls", "1e12 written as YAML 1.2 reads", ["scene", "check", "s.yaml"],
        files={"s.yaml": scene("noise: {sigma_counts: 1e2}\n")}, expect="ok")

    # --- YAML bombs and hostile structure
    laughs = "name: lol\n" + "a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
        f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n" for i in range(1, 10))
    add("yaml_bombs", "billion laughs", ["scene", "check", "s.yaml"], files={"s.yaml": laughs},
        limits={"RLIMIT_AS": 2 << 30})
    add("yaml_bombs", "self-referencing alias", ["scene", "check", "s.yaml"],
        files={"s.yaml": "name: x\ntargets: &t {points: *t}\n"})
    add("yaml_bombs", "deep flow nesting", ["scene", "check", "s.yaml"],
        files={"s.yaml": "name: x\nd: " + "[" * 20000 + "]" * 20000 + "\n"})
    add("yaml_bombs", "deep block nesting", ["scene", "check", "s.yaml"],
        files={"s.yaml": "name: x\n" + "".join("  " * i + f"k{i}:\n" for i in range(200)) + "  " * 200 + "v: 1\n"})
    add("yaml_bombs", "a 3 MB scene file", ["scene", "check", "s.yaml"],
        files={"s.yaml": "name: x\n" + "# padding\n" * 300_000})
    add("yaml_bombs", "anchors in a settings file", ["count", "d.nc", "--settings", "p.yaml"],
        files={"d.nc": _dataset("good"), "p.yaml": "detect: &d {method: fixed}\ncount: *d\n"})
    add("yaml_bombs", "alias bomb in a dataset's provenance", ["count", "d.nc"],
        files={"d.nc": _dataset("bad_provenance")})
    add("yaml_bombs", "python object tag", ["scene", "check", "s.yaml"],
        files={"s.yaml": "name: !!python/object/apply:os.system ['echo pwned']\n"})

    # --- malformed YAML and files that are not scenes
    for name, text in [("syntax error", "name: x\nsonar: {mode: [normal\n"),
                       ("tab indentation", "name: x\nsonar:\n\tmode: normal\n"),
                       ("empty file", ""), ("only a comment", "# nothing\n"),
                       ("a list at the top", "- name: x\n"), ("a scalar at the top", "just text\n"),
                       ("duplicate key", "name: x\nname: y\n"), ("non-string key", "name: x\n1: 2\n"),
                       ("boolean key", "name: x\non: 1\n"), ("unclosed quote", "name: 'x\n"),
                       ("two documents", "name: x\n---\nname: y\n")]:
        add("malformed_yaml", name, ["scene", "check", "s.yaml"], files={"s.yaml": text})
    add("malformed_yaml", "binary file", ["scene", "check", "s.yaml"], files={"s.yaml": b"\xff\xfe\x00\x01" * 50})
    add("malformed_yaml", "a folder as the scene", ["scene", "check", "d"], setup=lambda f: (f / "d").mkdir())
    add("malformed_yaml", "a device as the scene", ["scene", "check", "/dev/zero"], timeout=20)
    add("malformed_yaml", "missing file", ["run", "nope.yaml", "-o", "out"])
    add("malformed_yaml", "/etc/passwd as the scene", ["scene", "check", "/etc/passwd"])

    # --- values the schema must refuse
    bad_values = {
        "count as text": "pings: {count: '3'}\n", "negative pings": "pings: {count: -1}\n",
        "zero pings": "pings: {count: 0}\n", "nan sound speed": "medium: {sound_speed_m_s: .nan}\n",
        "inf rate": "sampling: {rate_hz: .inf}\n", "boolean bandwidth": "signal: {bandwidth_hz: true}\n",
        "negative duration": "signal: {duration_s: -0.007}\n", "unknown key": "colour: blue\n",
        "unknown nested key": "sonar: {colour: blue}\n", "bad mode": "sonar: {mode: sideways}\n",
        "bad taper": "signal: {taper: triangle}\n", "bad window": "processing: {image: {range_window: x}}\n",
        "elevation over 90°": "targets:\n  points:\n    - {range_m: 17, azimuth_deg: 0, elevation_deg: 95}\n",
        "range interval reversed": "processing: {image: {range_m: [20, 13]}}\n",
        "count and density": "targets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [-1,1], y_m: [-1,1], z_m: [15,16], count: 3, density_per_m3: 1}\n",
        "cuboid low above high": "targets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [1,-1], y_m: [-1,1], z_m: [15,16], count: 3}\n",
        "temperature 90 °C": "medium: {temperature_c: 90}\n", "salinity negative": "medium: {salinity_psu: -3}\n",
        "pH 14": "medium: {ph: 14}\n", "kernel length 1": "effects: {kernel_length: 1}\n",
        "oversampling 100": "effects: {oversampling: 100}\n", "multipath order 9": "effects: {multipath_order: 9}\n",
        "max bounces 9": "effects: {max_bounces: 9}\n",
        "ADC bits 64": "sampling: {adc: {bits: 64}}\n", "bad start time": "pings: {start_time: yesterday}\n",
        "start time in 3000": "pings: {start_time: '3000-01-01T00:00:00'}\n",
        "bandwidth over the rate": "sampling: {rate_hz: 10000}\n",
        "f0 below half the band": "signal: {center_frequency_hz: 5000}\n",
        "TS of +100 dB": "targets:\n  points:\n    - {range_m: 17, azimuth_deg: 0, elevation_deg: 0, backscatter: {model: fixed, ts_db: 100}}\n",
        "Rayleigh lo above hi": "targets:\n  points:\n    - {range_m: 17, azimuth_deg: 0, elevation_deg: 0, backscatter: {model: rayleigh, lo_m: 2, hi_m: 1}}\n",
        "zero boresight": "sonar: {pose: {boresight: [0, 0, 0]}}\n",
        "boresight along the receiver": "sonar: {pose: {boresight: [0, 1, 0]}}\n",
        "threshold value negative": "processing: {detect: {method: fixed, value: -5}}\n",
        "pfa above 1": "processing: {detect: {pfa_image: 2}}\n",
        "schema version 2": "schema_version: 2\n",
    }
    for name, extra in bad_values.items():
        add("schema_values", name, ["run", "s.yaml", "-o", "out"], files={"s.yaml": scene(extra)})

    # --- overflowing values
    overflow = {"seed 2^70": "seed: 1180591620717411303424\n", "sound speed 1e12": "medium: {sound_speed_m_s: 1.0e12}\n",
                "ping interval 1e20": "pings: {interval_s: 1.0e20}\n", "f0 1e15": "signal: {center_frequency_hz: 1.0e15}\n",
                "ADC scale 1e300": "sampling: {adc: {scale_counts: 1.0e300}}\n", "rate 1e300": "sampling: {rate_hz: 1.0e300}\n",
                "samples 1e12": "sampling: {samples: 1000000000000}\n", "pings 1e18": "pings: {count: 1000000000000000000}\n",
                "first ping 2^62": "pings: {first: 4611686018427387904}\n", "time offset 1e30": "sampling: {time_offset_s: 1.0e30}\n",
                "noise sigma 1e300": "noise: {enabled: true, sigma_counts: 1.0e300}\n",
                "floor size 1e300": "boundaries:\n  - {name: f, role: floor, mesh: {shape: plane, center_m: [0,0,30], size_m: [1.0e300, 1.0e300]}}\n",
                "target at 1e300 m": "targets:\n  points:\n    - {frame: world, position_m: [0, 0, 1.0e300]}\n",
                "density 1e30": "targets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [-1,1], y_m: [-1,1], z_m: [15,16], density_per_m3: 1.0e30}\n"}
    for name, extra in overflow.items():
        add("overflow_values", name, ["run", "s.yaml", "-o", "out"], files={"s.yaml": scene(extra)})

    # --- sizes nobody can run: refused up front (exit 3), with the estimate
    no_sampling = BASE.replace("sampling: {samples: 1024, time_offset_s: 0.017}\n", "")
    no_targets = BASE.split("targets:")[0]
    sizes = {"10^7 pings of 4096 samples": ("pings: {count: 10000000}\nsampling: {samples: 4096}\n", no_sampling),
             "4 M samples x 1000 pings": ("sampling: {samples: 4000000}\npings: {count: 1000}\n", no_sampling),
             "10^7 targets": ("targets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [-1,1], y_m: [-1,1], z_m: [15,16], count: 10000000}\n", no_targets),
             "floor at 1 mm resolution": ("boundaries:\n  - {name: f, role: floor, mesh: {shape: rough_floor, depth_m: 30, size_m: [1000, 1000], resolution_m: 0.001}}\n", BASE),
             "plane of 10^5 x 10^5 segments": ("boundaries:\n  - {name: f, role: floor, mesh: {shape: plane, center_m: [0,0,30], segments: [100000, 100000]}}\n", BASE),
             "10^6 rays per square degree": ("boundaries:\n  - {name: f, role: floor, mesh: {shape: plane, center_m: [0,0,30]}}\neffects: {reverberation: {enabled: true, rays_per_square_degree: 1000000}}\n", BASE),
             "huygens with 10^8 targets": ("effects: {directivity: huygens}\ntargets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [-1,1], y_m: [-1,1], z_m: [15,16], count: 100000000}\n", no_targets),
             "a density of 10^5 per m³ over 10^4 m³": ("targets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [-50,50], y_m: [-50,50], z_m: [15,16], density_per_m3: 100000}\n", no_targets)}
    for name, (extra, base) in sizes.items():
        # the rough floor has a limit of its own (exit 2, naming it); the rest are estimates (3).
        # 10^7 targets need ≈ 2.3 GB: refused under a 1 GB limit on any machine (the default
        # limit, half the machine's memory, lets a 24 GB machine run it — for minutes)
        add("impossible_sizes", name, ["run", "s.yaml", "-o", "out"], files={"s.yaml": scene(extra, base=base)},
            status=None if "1 mm" in name else 3,
            env={"ABACUS_MAX_MEMORY_GB": "1"} if name == "10^7 targets" else {})
    add("impossible_sizes", "scene check says the same", ["scene", "check", "s.yaml"],
        files={"s.yaml": scene("pings: {count: 10000000}\n")}, status=3)
    add("impossible_sizes", "--pings 10^8", ["simulate", "s.yaml", "-o", "s.nc", "--pings", "100000000"],
        files={"s.yaml": BASE}, status=3)
    add("impossible_sizes", "a memory limit of 50 MB", ["run", "s.yaml", "-o", "out", "--max-memory", "0.05"],
        files={"s.yaml": BASE}, status=3)

    # --- physically impossible scenes
    phys = {"target above the surface": "  - {frame: world, position_m: [0, 0, -2]}\n",
            "target in the air above the sonar": "  - {range_m: 5, azimuth_deg: 0, elevation_deg: 0}\n"}
    add("impossible_physics", "target above the surface", ["run", "s.yaml", "-o", "out"],
        files={"s.yaml": scene("", base=BASE.replace("  points:\n", "  points:\n" + phys["target above the surface"]))})
    add("impossible_physics", "sonar looking up at a target in the air", ["run", "s.yaml", "-o", "out"],
        files={"s.yaml": scene("sonar: {pose: {boresight: [0, 0, -1]}}\n")})
    add("impossible_physics", "population above the surface", ["run", "s.yaml", "-o", "out"],
        files={"s.yaml": scene("targets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [-1,1], y_m: [-1,1], z_m: [-3, 5], count: 3}\n",
                               base=BASE.split("targets:")[0])})
    add("impossible_physics", "target below a flat floor", ["run", "s.yaml", "-o", "out"],
        files={"s.yaml": scene("boundaries:\n  - {name: f, role: floor, mesh: {shape: plane, center_m: [0,0,18]}}\n")})
    add("impossible_physics", "population below a rough floor", ["run", "s.yaml", "-o", "out"],
        files={"s.yaml": scene("boundaries:\n  - {name: f, role: floor, mesh: {shape: rough_floor, depth_m: 20}}\n"
                               "targets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [-1,1], y_m: [-1,1], z_m: [15, 25], count: 3}\n",
                               base=BASE.split("targets:")[0])})
    add("impossible_physics", "sonar above the surface", ["run", "s.yaml", "-o", "out"],
        files={"s.yaml": scene("sonar: {pose: {position_m: [0, 0, -3]}}\n")})

    # --- paths a scene may not read
    def floor_file(path):
        return scene(f"boundaries:\n  - {{name: f, role: floor, mesh: {{shape: height_grid, file: '{path}', spacing_m: [1, 1]}}}}\n")
    add("paths", "grid file /etc/passwd", ["run", "s.yaml", "-o", "out"], files={"s.yaml": floor_file("/etc/passwd")})
    add("paths", "mesh file /etc/passwd", ["run", "s.yaml", "-o", "out"],
        files={"s.yaml": scene("boundaries:\n  - {name: r, role: obstacle, mesh: {shape: file, file: /etc/passwd}}\n")})
    add("paths", "grid file ../outside.csv", ["scene", "check", "s/s.yaml"],
        files={"s/s.yaml": floor_file("../outside.csv"), "outside.csv": "1,2\n3,4\n"})
    add("paths", "symlink pointing outside", ["scene", "check", "s/s.yaml"],
        files={"s/s.yaml": floor_file("link.csv")},
        setup=lambda f: (f / "s" / "link.csv").symlink_to("/etc/passwd"))
    add("paths", "a folder as the grid", ["scene", "check", "s.yaml"], files={"s.yaml": floor_file("g")},
        setup=lambda f: (f / "g").mkdir())
    add("paths", "/dev/zero as the mesh", ["scene", "check", "s.yaml"], timeout=20,
        files={"s.yaml": scene("boundaries:\n  - {name: r, role: obstacle, mesh: {shape: file, file: /dev/zero}}\n")},
        env={"ABACUS_ALLOW_OUTSIDE_FILES": "1"})
    add("paths", "passwd copied in as a grid (contents not echoed)", ["scene", "check", "s.yaml"],
        files={"s.yaml": floor_file("g.csv")}, setup=lambda f: shutil.copy("/etc/passwd", f / "g.csv"))
    add("paths", "passwd copied in as an OBJ", ["scene", "check", "s.yaml"],
        files={"s.yaml": scene("boundaries:\n  - {name: r, role: obstacle, mesh: {shape: file, file: m.obj}}\n")},
        setup=lambda f: shutil.copy("/etc/passwd", f / "m.obj"))
    add("paths", "missing grid file", ["scene", "check", "s.yaml"], files={"s.yaml": floor_file("none.csv")})
    add("paths", "a pickled .npy grid", ["scene", "check", "s.yaml"], files={"s.yaml": floor_file("g.npy")},
        setup=lambda f: __import__("numpy").save(f / "g.npy", __import__("numpy").array([{"a": 1}], dtype=object),
                                                 allow_pickle=True))
    add("paths", "--settings /etc/passwd", ["count", "d.nc", "--settings", "/etc/passwd"],
        files={"d.nc": _dataset("good")})
    add("paths", "noise file /etc/passwd", ["count", "d.nc", "--settings", "p.yaml"],
        files={"d.nc": _dataset("good"), "p.yaml": "detect: {noise: {source: noise_file, file: /etc/passwd}}\n"})

    # --- scene names that try to leave runs/
    for name in ("../../escaped", "/tmp/abs-escape", "..", "a/../../b"):
        add("scene_name_traversal", f"name {name!r}", ["run", "s.yaml", "--no-plots"],
            files={"s.yaml": BASE.replace("name: probe", f"name: '{name}'")}, expect="ok", keep=("runs",))

    # --- meshes that are not meshes
    def mesh_scene(file):
        return scene(f"boundaries:\n  - {{name: r, role: obstacle, mesh: {{shape: file, file: {file}, repair: false}}}}\n")
    add("bad_meshes", "empty OBJ", ["scene", "check", "s.yaml"], files={"s.yaml": mesh_scene("m.obj"), "m.obj": ""})
    add("bad_meshes", "NaN vertices", ["scene", "check", "s.yaml"],
        files={"s.yaml": mesh_scene("m.obj"), "m.obj": "v 0 0 20\nv nan 0 20\nv 0 1 20\nf 1 2 3\n"})
    add("bad_meshes", "faces past the vertices", ["scene", "check", "s.yaml"],
        files={"s.yaml": mesh_scene("m.obj"), "m.obj": "v 0 0 20\nv 1 0 20\nv 0 1 20\nf 1 2 9\n"})
    add("bad_meshes", "text as STL", ["scene", "check", "s.yaml"],
        files={"s.yaml": mesh_scene("m.stl"), "m.stl": "solid nothing here at all\n"})
    add("bad_meshes", "degenerate faces, repair off", ["scene", "check", "s.yaml"],
        files={"s.yaml": mesh_scene("m.obj"), "m.obj": "v 0 0 20\nv 1 0 20\nv 2 0 20\nf 1 2 3\n"})
    add("bad_meshes", "random bytes as PLY", ["scene", "check", "s.yaml"],
        files={"s.yaml": mesh_scene("m.ply"), "m.ply": os.urandom(3000)})
    add("bad_meshes", "grid of one height", ["scene", "check", "s.yaml"],
        files={"s.yaml": floor_file("g.csv"), "g.csv": "5\n"})
    add("bad_meshes", "grid with NaN", ["scene", "check", "s.yaml"],
        files={"s.yaml": floor_file("g.csv"), "g.csv": "30,30\nnan,30\n"})
    add("bad_meshes", "unknown mesh suffix", ["scene", "check", "s.yaml"],
        files={"s.yaml": mesh_scene("m.xyz"), "m.xyz": "1 2 3\n"})

    # --- datasets processing cannot use
    for kind in ("text", "empty", "truncated", "hdf5_garbage", "no_sonar", "no_samples", "no_element_group",
                 "nan_samples", "no_imaginary_part", "bad_mode", "zero_interval", "zero_replica", "wrong_dims",
                 "no_sound_speed"):
        add("bad_datasets", f"count: {kind.replace('_', ' ')}", ["count", "d.nc", "-o", "c.nc"], files={"d.nc": _dataset(kind)})
    add("bad_datasets", "image: truncated", ["image", "d.nc", "-o", "i.nc"], files={"d.nc": _dataset("truncated")})
    add("bad_datasets", "image: a folder that is not Zarr", ["image", "d.zarr", "-o", "i.nc"],
        setup=lambda f: (f / "d.zarr").mkdir())
    add("bad_datasets", "missing dataset", ["count", "none.nc"])
    add("bad_datasets", "a device as the dataset", ["count", "/dev/zero"], timeout=20)
    add("bad_datasets", "image --ping past the end", ["image", "d.nc", "--plots", "p", "--ping", "7"],
        files={"d.nc": _dataset("good")})

    # --- options
    opts = [("--pings 0", ["simulate", "s.yaml", "-o", "s.nc", "--pings", "0"]),
            ("--pings -5", ["run", "s.yaml", "-o", "out", "--pings", "-5"]),
            ("--pings abc", ["run", "s.yaml", "-o", "out", "--pings", "abc"]),
            ("--seed -1", ["simulate", "s.yaml", "-o", "s.nc", "--seed", "-1"]),
            ("--seed 2^70", ["simulate", "s.yaml", "-o", "s.nc", "--seed", str(2 ** 70)]),
            ("--sweep without =", ["experiment", "s.yaml", "-o", "e", "--sweep", "threshold"]),
            ("--sweep bad range", ["experiment", "s.yaml", "-o", "e", "--sweep", "threshold=5:1:1"]),
            ("--sweep zero step", ["experiment", "s.yaml", "-o", "e", "--sweep", "threshold=1:5:0"]),
            ("--sweep text values", ["experiment", "s.yaml", "-o", "e", "--sweep", "threshold=a,b"]),
            ("--sweep unknown key", ["experiment", "s.yaml", "-o", "e", "--sweep", "colour=1,2"]),
            ("--sweep 10^6 points", ["experiment", "s.yaml", "-o", "e", "--sweep", "threshold=0:1000000:1"]),
            ("--sweep a value the schema refuses", ["experiment", "s.yaml", "-o", "e", "--sweep", "noise.sigma_counts=-1,2"]),
            ("--workers -1", ["experiment", "s.yaml", "-o", "e", "--workers", "-1"]),
            ("--track-pings 1", ["experiment", "s.yaml", "-o", "e", "--pings", "4", "--track-pings", "1"]),
            ("--track-pings beyond the pings", ["experiment", "s.yaml", "-o", "e", "--pings", "4", "--track-pings", "9"]),
            ("--track-pings text", ["experiment", "s.yaml", "-o", "e", "--track-pings", "x"]),
            ("--format xml", ["simulate", "s.yaml", "-o", "s.nc", "--format", "xml"]),
            ("unknown option", ["run", "s.yaml", "--colour"]),
            ("no command", []),
            ("unknown command", ["fly"]),
            ("--max-memory -1", ["run", "s.yaml", "-o", "out", "--max-memory", "-1"]),
            ("--settings missing", ["count", "d.nc", "--settings", "none.yaml"]),
            ("--settings with a bad key", ["count", "d.nc", "--settings", "p.yaml"]),
            ("image with neither -o nor --plots", ["image", "d.nc"]),
            ("view without -o", ["view", "s.yaml"])]
    for name, argv in opts:
        add("bad_options", name, argv, files={"s.yaml": BASE, "d.nc": _dataset("good"),
                                              "p.yaml": "detect: {colour: red}\n"})

    # --- outputs that are there already, or cannot be
    add("output_collisions", "simulate -o an existing file", ["simulate", "s.yaml", "-o", "s.nc"],
        files={"s.yaml": BASE, "s.nc": "keep me"})
    add("output_collisions", "simulate -o an existing folder", ["simulate", "s.yaml", "-o", "d"],
        files={"s.yaml": BASE}, setup=lambda f: (f / "d").mkdir())
    add("output_collisions", "simulate into a missing folder", ["simulate", "s.yaml", "-o", "no/such/s.nc"],
        files={"s.yaml": BASE})
    add("output_collisions", "count --csv an existing file", ["count", "d.nc", "--csv", "c.csv"],
        files={"d.nc": _dataset("good"), "c.csv": "keep me"})
    add("output_collisions", "image -o the input itself", ["image", "d.nc", "-o", "d.nc"],
        files={"d.nc": _dataset("good")})
    add("output_collisions", "run -o an existing file", ["run", "s.yaml", "-o", "f"], files={"s.yaml": BASE, "f": "x"})
    add("output_collisions", "run -o an existing run", ["run", "s.yaml", "-o", "out", "--no-plots"],
        files={"s.yaml": BASE, "out/run.nc": "old"})
    add("output_collisions", "experiment -o a folder of other files", ["experiment", "s.yaml", "-o", "e", "--workers", "0"],
        files={"s.yaml": BASE, "e/thesis.pdf": "mine"})
    add("output_collisions", "experiment -o a file", ["experiment", "s.yaml", "-o", "e", "--workers", "0"],
        files={"s.yaml": BASE, "e": "a file"})
    add("output_collisions", "simulate into a read-only folder", ["simulate", "s.yaml", "-o", "disk/s.nc"],
        files={"s.yaml": BASE}, tmpfs_mb=4, readonly=True, keep=("disk",))
    add("output_collisions", "view -o an existing picture", ["view", "s.yaml", "-o", "v.png"],
        files={"s.yaml": BASE, "v.png": "keep"})

    # --- experiment state
    def exp_then(damage):
        def setup(folder):
            r = subprocess.run(ABACUS + ["experiment", "s.yaml", "--pings", "2", "--workers", "0", "-o", "exp"],
                               cwd=folder, env=_env(), capture_output=True, text=True)
            if r.returncode:
                raise RuntimeError(r.stderr)
            damage(folder / "exp")
        return setup
    run_exp = ["experiment", "s.yaml", "--pings", "2", "--workers", "0", "-o", "exp"]
    add("experiment_state", "truncated part (recomputed)", run_exp, files={"s.yaml": BASE}, expect="ok", keep=("exp",),
        setup=exp_then(lambda e: (e / "parts" / "ping000000.npz").write_bytes(
            (e / "parts" / "ping000000.npz").read_bytes()[:100])), timeout=120)
    add("experiment_state", "empty part (recomputed)", run_exp, files={"s.yaml": BASE}, expect="ok", keep=("exp",),
        setup=exp_then(lambda e: (e / "parts" / "ping000001.npz").write_bytes(b"")), timeout=120)
    add("experiment_state", "empty manifest (parts say whose they are)", run_exp, files={"s.yaml": BASE},
        expect="ok", keep=("exp",), setup=exp_then(lambda e: (e / "experiment.json").write_text("")), timeout=120)
    add("experiment_state", "manifest deleted, parts of another scene", run_exp,
        files={"s.yaml": BASE.replace("seed", "seed").replace("name: probe", "name: other\nseed: 99")},
        keep=("exp",), timeout=120,
        setup=lambda f: ((f / "s2.yaml").write_text(BASE),
                         subprocess.run(ABACUS + ["experiment", "s2.yaml", "--pings", "2", "--workers", "0",
                                                  "-o", "exp"], cwd=f, env=_env(), capture_output=True, check=True),
                         (f / "exp" / "experiment.json").unlink()))
    add("experiment_state", "a part with a wrong checksum (recomputed)", run_exp, files={"s.yaml": BASE},
        expect="ok", keep=("exp",), timeout=120, setup=exp_then(_flip_byte))
    add("experiment_state", "parts folder is a file", run_exp, files={"s.yaml": BASE}, keep=("exp",), timeout=120,
        setup=exp_then(lambda e: (shutil.rmtree(e / "parts"), (e / "parts").write_text("x"))))

    # --- interrupts: prompt, clean, and a later run completes
    # slow enough that every interrupt lands mid-run: 400 pings had come to take 4–5 s, and a
    # quiet machine finished them before the SIGKILL at 4 s (the probe then found s.nc written)
    slow = scene("pings: {count: 1200}\nsampling: {samples: 4096, time_offset_s: 0.0}\nnoise: {enabled: true}\n",
                 base=BASE.replace("sampling: {samples: 1024, time_offset_s: 0.017}\n", ""))
    for when in (0.8, 2.5, 5.0):
        add("interrupts", f"SIGINT during simulate at {when} s", ["simulate", "s.yaml", "-o", "s.nc"],
            files={"s.yaml": slow}, interrupt=(signal.SIGINT, when), status=130, timeout=60)
    add("interrupts", "SIGINT during run", ["run", "s.yaml", "-o", "out"], files={"s.yaml": slow},
        interrupt=(signal.SIGINT, 3.0), status=130, timeout=60)
    add("interrupts", "SIGTERM during run", ["run", "s.yaml", "-o", "out"], files={"s.yaml": slow},
        interrupt=(signal.SIGTERM, 3.0), status=143, timeout=60)
    add("interrupts", "SIGINT during an experiment (then resumed)",
        ["experiment", "s.yaml", "--pings", "40", "--workers", "0", "-o", "exp"], files={"s.yaml": slow},
        interrupt=(signal.SIGINT, 4.0), status=130, timeout=60, keep=("exp",),
        then=["experiment", "s.yaml", "--pings", "40", "--workers", "0", "-o", "exp"])
    add("interrupts", "SIGKILL during simulate (then rerun)", ["simulate", "s.yaml", "-o", "s.nc"],
        files={"s.yaml": slow}, interrupt=(signal.SIGKILL, 4.0), status=-9, timeout=60, keep=("s.nc",),
        then=["simulate", "s.yaml", "-o", "s.nc", "--pings", "3"])
    add("interrupts", "SIGKILL during run (then rerun)", ["run", "s.yaml", "-o", "out"], files={"s.yaml": slow},
        interrupt=(signal.SIGKILL, 4.0), status=-9, timeout=60, keep=("out",),
        then=["run", "s.yaml", "-o", "out", "--pings", "2", "--no-plots"])

    # --- a full disk, and memory limits
    add("resources", "simulate onto a 2 MB disk", ["simulate", "s.yaml", "-o", "disk/s.nc", "--pings", "10"],
        files={"s.yaml": scene("sampling: {samples: 4096}\n")}, tmpfs_mb=2, keep=("disk",))
    add("resources", "run onto a 2 MB disk", ["run", "s.yaml", "-o", "disk/out", "--pings", "10"],
        files={"s.yaml": scene("sampling: {samples: 4096}\n")}, tmpfs_mb=2, keep=("disk",))
    add("resources", "files limited to 1 MB (RLIMIT_FSIZE)", ["simulate", "s.yaml", "-o", "s.nc", "--pings", "10"],
        files={"s.yaml": scene("sampling: {samples: 4096}\n")}, limits={"RLIMIT_FSIZE": 1 << 20})
    add("resources", "alias bomb under a 1 GB address space", ["scene", "check", "s.yaml"],
        files={"s.yaml": laughs}, limits={"RLIMIT_AS": 1 << 30})
    add("resources", "count with a 100 MB memory limit", ["count", "d.nc", "--max-memory", "0.0001"],
        files={"d.nc": _dataset("good")}, status=3)
    _issue27_probes(add)
    return P


#: a motion file the scene reads (sonar.motion.kind: file)
MOTION = "sonar: {motion: {kind: file, file: m.csv}}\npings: {interval_s: 0.5}\n"
GOOD_MOTION = "time_s,roll_deg,pitch_deg,heave_m\n0,0,0,0\n1,2,1,0.2\n2,0,-1,0\n"
#: a swell over the probe's targets (surface at z = 0, the sonar at 5 m depth)
SWELL = """\
sonar: {{pose: {{position_m: [0, 0, {depth}], boresight: [1, 0, 0], receiver_axis: [0, 1, 0]}}}}
targets:
  points:
    - {{frame: world, position_m: [{x}, 0, {z}]}}
boundaries:
  - name: sea
    role: surface
    mesh: {{shape: swell, center_m: [15, 0], size_m: [{length}, 16], resolution_m: {res},
            waves: [{{amplitude_m: {amp}, wavelength_m: {wl}}}]}}
pings: {{count: {pings}, interval_s: 0.25}}
effects: {{multipath_order: 1}}
"""


def _swell(x=17.0, z=2.0, amp=0.5, wl=25.0, res=0.5, pings=4, depth=5.0, length="40"):
    return scene(SWELL.format(x=x, z=z, amp=amp, wl=wl, res=res, pings=pings, depth=depth, length=length))


def _mat(kind: str):
    """A writer of a small MATLAB recording (2 pings, 32 elements A/B), good or damaged one way."""
    def make(path: Path):
        import numpy as np
        from scipy.io import savemat
        rng = np.random.default_rng(1)
        n_el, n_s, fs = 32, 512, 150e3
        t = np.arange(200) / fs
        fields = {
            "samples": (rng.standard_normal((2, n_el, n_s)) + 1j * rng.standard_normal((2, n_el, n_s))),
            "fs": fs, "f0": 420e3, "bandwidth": 30e3, "c": 1500.0,
            "replica": np.exp(1j * np.pi * 30e3 / t[-1] * (t - t[-1] / 2) ** 2),
            "element_xyz": np.column_stack([np.arange(n_el) * 0.003, np.zeros(n_el), np.zeros(n_el)]),
            "element_subarray": np.array(["A"] * 16 + ["B"] * 16, dtype=object),
            "tx_xyz": np.column_stack([np.zeros(16), np.arange(16) * 0.003, np.zeros(16)]),
            "ping_time": np.array([0.0, 0.1]),
        }
        if kind == "nan_times":
            fields["ping_time"] = np.array([0.0, np.nan])
        elif kind == "decreasing_times":
            fields["ping_time"] = np.array([0.1, 0.0])
        elif kind == "sound_speed_1e12":
            fields["c"] = 1e12
        elif kind == "empty_replica":
            fields["replica"] = np.zeros(0, complex)
        elif kind == "subarrays_all_c":
            fields["element_subarray"] = np.array(["C"] * n_el, dtype=object)
        elif kind == "text_rate":
            fields["fs"] = "fast"
        elif kind == "char_row_subarray":
            fields["element_subarray"] = "A" * 16 + "B" * 16
        savemat(path, fields)
    return make


def _strict_json(folder: Path, out: str):
    """None when the command printed strict JSON (no NaN or Infinity), else why not."""
    import json

    def refuse(token):
        raise ValueError(f"{token} is not JSON")
    try:
        json.loads(out, parse_constant=refuse)
    except ValueError as exc:
        return f"stdout is not strict JSON ({exc})"
    return None


def _issue27_probes(add):
    """Issue 27's classes: motion files, files out of bounds, size drivers, values the checks
    must catch, geometry out of the water, convert, outputs, output sets."""
    motion_scene = scene(MOTION)
    # 1. motion files are user input
    add("controls", "a good motion file", ["scene", "check", "s.yaml"],
        files={"s.yaml": motion_scene, "m.csv": GOOD_MOTION}, expect="ok")
    bad_motion = {
        "no time_s column": "t,roll_deg\n0,1\n",
        "NaN roll": "time_s,roll_deg\n0,0\n1,nan\n",
        "time going back": "time_s,roll_deg\n0,0\n2,1\n1,0\n",
        "empty file": "",
        "header only": "time_s,roll_deg\n",
        "semicolons": "time_s;roll_deg\n0;0\n1;1\n",
        "ragged row": "time_s,roll_deg\n0,0\n1\n",
        "binary bytes": b"\x00\xff\xfe\x01" * 64,
        "heave 400 m": "time_s,heave_m\n0,0\n1,400\n",
        "roll 500 degrees": "time_s,roll_deg\n0,0\n1,500\n",
    }
    for name, text in bad_motion.items():
        add("motion_files", name, ["scene", "check", "s.yaml"],
            files={"s.yaml": motion_scene, "m.csv": text}, says=("m.csv",))
    add("motion_files", "missing file", ["simulate", "s.yaml", "-o", "s.nc"], files={"s.yaml": motion_scene},
        says=("m.csv",))
    add("motion_files", "a folder", ["scene", "check", "s.yaml"], files={"s.yaml": motion_scene},
        setup=lambda f: (f / "m.csv").mkdir(), says=("m.csv",))
    # 2. files that escape the scene's folder, or are not files
    for name, target in [("../outside.csv", "../outside.csv"), ("an absolute system path", "/etc/passwd"),
                         ("/dev/zero", "/dev/zero")]:
        add("user_files", f"motion file {name}", ["scene", "check", "s.yaml"], timeout=30,
            files={"s.yaml": scene(MOTION.replace("m.csv", target))}, says=("sonar.motion",))
    add("user_files", "motion file a symlink out of the folder", ["scene", "check", "s.yaml"],
        files={"s.yaml": motion_scene}, setup=lambda f: os.symlink("/etc/passwd", f / "m.csv"),
        says=("m.csv",))
    add("user_files", "motion file a FIFO", ["scene", "check", "s.yaml"], files={"s.yaml": motion_scene},
        setup=lambda f: os.mkfifo(f / "m.csv"), timeout=20, says=("m.csv",))
    add("user_files", "noise file an absolute system path", ["scene", "check", "s.yaml"],
        files={"s.yaml": scene("processing: {detect: {noise: {source: noise_file, file: /etc/passwd}}}\n")},
        says=("noise",))
    # 3. size drivers the estimate must see before anything is allocated
    add("size_drivers", "a school of 5 x 10^7 fish", ["scene", "check", "s.yaml"], status=3,
        files={"s.yaml": scene("targets:\n  populations:\n    - {kind: school, center_m: [0, 0, 18], "
                               "semi_axes_m: [2, 2, 2], count: 50000000}\n")})
    add("size_drivers", "a plane of 10^12 facets", ["scene", "check", "s.yaml"], status=3,
        files={"s.yaml": scene("boundaries:\n  - {name: f, role: floor, mesh: {shape: plane, center_m: [0, 0, 25], "
                               "normal: [0, 0, 1], size_m: [40, 40], segments: [1000000, 1000000]}}\n")})
    add("size_drivers", "a PLY header claiming 10^12 faces", ["scene", "check", "s.yaml"],
        files={"s.yaml": scene("boundaries:\n  - {name: r, role: obstacle, mesh: {shape: file, file: m.ply}}\n"),
               "m.ply": "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                        "property float y\nproperty float z\nelement face 1000000000000\n"
                        "property list uchar int vertex_indices\nend_header\n"})
    add("size_drivers", "sv --range-bin 1e-9", ["sv", "d.nc", "--range-bin", "1e-9", "--csv", "m.csv"],
        files={"d.nc": _dataset("good")}, says=("--range-bin",))
    # 4. values a scene check must catch before a run fails on them
    floor = ("boundaries:\n  - name: floor\n    role: floor\n    mesh: {shape: rough_floor, depth_m: 30.0, "
             "size_m: [40.0, 40.0], resolution_m: 0.5, rms_height_m: 0.1, correlation_length_m: 1.5}\n")
    add("checked_values", "floor tiles with 0.01 MB of memory", ["run", "s.yaml", "-o", "out"],
        files={"s.yaml": scene(floor + "effects: {floor_tiles: {enabled: true, memory_mb: 0.01}}\n")},
        says=("memory_mb",))
    add("checked_values", "a negative radial speed for single targets", ["scene", "check", "s.yaml"],
        files={"s.yaml": scene("processing: {single_target: {maximum_radial_speed_m_s: -1}}\n")},
        says=("maximum_radial_speed_m_s",))
    add("checked_values", "an unknown count.volume_edge", ["scene", "check", "s.yaml"],
        files={"s.yaml": scene("processing: {count: {volume_edge: fuzzy}}\n")}, says=("volume_edge",))
    add("checked_values", "image range outside the record", ["scene", "check", "s.yaml"],
        files={"s.yaml": scene("processing: {image: {range_m: [40.0, 60.0]}}\n")}, says=("range_m",))
    add("checked_values", "swell resolution 1e-300 m", ["scene", "check", "s.yaml"],
        files={"s.yaml": _swell(res=1e-300)}, says=("resolution_m",))
    add("checked_values", "swell size 1e300 m", ["scene", "check", "s.yaml"],
        files={"s.yaml": _swell(length="1.0e+300")}, says=("size_m",))
    add("checked_values", "a flat OBJ as a mesh target", ["simulate", "s.yaml", "-o", "s.nc"],
        files={"s.yaml": scene("targets:\n  meshes:\n    - {name: plate, frame: sonar, mesh: {shape: file, "
                               "file: m.obj, transform: {translate_m: [0, 0, 17]}}}\n"),
               "m.obj": "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0.1 0.1 0\nf 1 2 3\nf 2 4 3\n"}, expect="any",
        keep=("s.nc",))
    # 5. out of the water
    add("controls", "a target under a swell", ["scene", "check", "s.yaml"], files={"s.yaml": _swell()},
        expect="ok")
    add("out_of_water", "a target in the swell's crests", ["scene", "check", "s.yaml"],
        files={"s.yaml": _swell(z=-0.2)}, says=("targets",))
    add("out_of_water", "the sonar above the surface", ["scene", "check", "s.yaml"],
        files={"s.yaml": _swell(depth=-1.0)}, says=("sonar",))
    add("out_of_water", "swell amplitude 1e6 m", ["scene", "check", "s.yaml"],
        files={"s.yaml": _swell(amp=1e6)}, says=("amplitude_m",))
    add("out_of_water", "swell wavelength 1e-300 m", ["scene", "check", "s.yaml"],
        files={"s.yaml": _swell(wl=1e-300)}, says=("wavelength_m",))
    # 6. convert writes only what processing can use
    add("controls", "convert a good .mat", ["convert", "r.mat", "r.nc"], files={"r.mat": _mat("good")},
        expect="ok", keep=("r.nc",))
    add("controls", "convert a .mat with MATLAB's char-row subarrays", ["convert", "r.mat", "r.nc"],
        files={"r.mat": _mat("char_row_subarray")}, expect="ok", keep=("r.nc",))
    for kind, word in [("nan_times", "ping_time"), ("decreasing_times", "ping_time"),
                       ("sound_speed_1e12", "c"), ("empty_replica", "replica"),
                       ("subarrays_all_c", "element_subarray"), ("text_rate", "fs")]:
        add("convert", kind.replace("_", " "), ["convert", "r.mat", "r.nc"], files={"r.mat": _mat(kind)},
            says=(word,))
    add("convert", "a FIFO as input", ["convert", "r.mat", "r.nc"], setup=lambda f: os.mkfifo(f / "r.mat"),
        timeout=20)
    # 7. outputs a program reads
    add("outputs", "track --json of one ping is strict JSON", ["track", "d.nc", "--json"],
        files={"d.nc": _dataset("good")}, expect="ok", check=_strict_json)
    add("outputs", "sv of a layer outside the image", ["sv", "d.nc", "--layer", "40:45", "--json"],
        files={"d.nc": _dataset("good")}, says=("--layer",))
    # 8. sets of outputs: all or nothing
    add("output_sets", "count -o, --csv, then an existing --targets-csv",
        ["count", "d.nc", "-o", "c.nc", "--csv", "c.csv", "--targets-csv", "t.csv"],
        files={"d.nc": _dataset("good"), "t.csv": "keep me"}, says=("t.csv",))
    add("output_sets", "--overwrite onto the input itself", ["count", "d.nc", "-o", "d.nc", "--overwrite"],
        files={"d.nc": _dataset("good")}, says=("d.nc",))
    add("output_sets", "experiment with an unreachable scheduler",
        ["experiment", "s.yaml", "-o", "exp", "--pings", "2", "--scheduler", "tcp://127.0.0.1:9"],
        files={"s.yaml": BASE}, timeout=90, says=("scheduler",))


def _flip_byte(exp: Path):
    import numpy as np
    import io
    part = exp / "parts" / "ping000000.npz"
    with np.load(part) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["seconds"] = np.asarray(float(arrays["seconds"]) + 1.0)   # contents no longer match
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    part.write_bytes(buf.getvalue())


# ------------------------------------------------------------------ running one
CACHE = Path(tempfile.gettempdir()) / "abacus-reliability"


def _env(extra=None):
    env = dict(os.environ, ABACUS_CACHE_DIR=str(CACHE / "geometry-cache"), MPLBACKEND="Agg",
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("ABACUS_ALLOW_OUTSIDE_FILES", None)
    env.update(extra or {})
    return env


def _listing(folder: Path) -> set:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")} if folder.exists() else set()


#: run by a fresh interpreter that then becomes the command (``os.execv``): the limits (and
#: SIGXFSZ ignored, so that a too-large write fails instead of killing) outlive the exec. Not a
#: ``preexec_fn``: that runs Python in the fork of a threaded process (the probes' pool, the
#: libraries' threads), which CPython documents as unsafe
_LIMITED = ("import json, os, resource, signal, sys\n"
            "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
            "for name, value in json.loads(sys.argv[1]).items():\n"
            "    resource.setrlimit(getattr(resource, name), (value, value))\n"
            "os.execv(sys.argv[2], sys.argv[2:])\n")


def _command(argv: list, limits: dict) -> list:
    """The probe's command line, under ``limits`` (resource name -> soft and hard limit)."""
    if not limits:
        return ABACUS + argv
    import json
    return [sys.executable, "-c", _LIMITED, json.dumps(limits)] + ABACUS + argv


def run_probe(probe: Probe) -> Result:
    box = Path(tempfile.mkdtemp(prefix="probe-", dir=CACHE / "boxes"))
    folder = box / "work"
    folder.mkdir()
    mounted = False
    try:
        for rel, content in probe.files.items():
            path = folder / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            if callable(content):
                content(path)
            elif isinstance(content, bytes):
                path.write_bytes(content)
            else:
                path.write_text(content)
        if probe.setup:
            probe.setup(folder)
        if probe.tmpfs_mb:
            (folder / "disk").mkdir()
            r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={int(probe.tmpfs_mb * 1024)}k",
                                "tmpfs", str(folder / "disk")], capture_output=True)
            mounted = r.returncode == 0
            if mounted and probe.readonly:
                subprocess.run(["mount", "-o", "remount,ro", str(folder / "disk")], capture_output=True)
            elif probe.readonly:   # not root: a folder without write permission stands in
                os.chmod(folder / "disk", 0o555)
            if not mounted:   # no permission to mount: a per-file size limit stands in
                probe.limits = {**probe.limits, "RLIMIT_FSIZE": int(probe.tmpfs_mb * 1024 * 1024)}
        before = _listing(folder)
        outside_before = {p.name for p in box.iterdir()}
        t0 = time.perf_counter()
        proc = subprocess.Popen(_command(probe.argv, probe.limits), cwd=folder, env=_env(probe.env),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        signalled_at = None
        try:
            if probe.interrupt:
                sig, when = probe.interrupt
                try:
                    proc.wait(timeout=when)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, sig) if sig == signal.SIGKILL else proc.send_signal(sig)
                    signalled_at = time.perf_counter()
            out, err = proc.communicate(timeout=probe.timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            return Result(probe, "hang", f"no exit within {probe.timeout:.0f} s", seconds=time.perf_counter() - t0)
        seconds = time.perf_counter() - t0
        rc = proc.returncode
        after = _listing(folder)
        new = sorted(p for p in after - before
                     if not any(p == k or p.startswith(k + "/") for k in probe.keep))
        temps = sorted(p for p in after if ".tmp-" in p or ".old-" in p)
        lines = [ln for ln in err.strip().splitlines() if ln.strip()]
        leaks = SECRET in err or SECRET in out
        outside = {p.name for p in box.iterdir()} - outside_before
        if "Traceback" in err:
            return Result(probe, "traceback", lines[-1][:200] if lines else "", err, seconds)
        if leaks:
            return Result(probe, "leak", "a file's contents appear in the output", err, seconds)
        if outside:
            return Result(probe, "outside", f"wrote outside its folder: {sorted(outside)}", err, seconds)
        if signalled_at is not None and probe.interrupt[0] != signal.SIGKILL:
            if time.perf_counter() - signalled_at > 5.0 + 0.5:
                return Result(probe, "slow interrupt", "took over 5 s to stop", err, seconds)
        if probe.status is not None and rc != probe.status and not (probe.interrupt and rc == 0):
            return Result(probe, "wrong exit", f"exit {rc}, expected {probe.status}", err, seconds)
        if probe.expect == "ok" and rc != 0:
            return Result(probe, "refused control", f"exit {rc}", err, seconds)
        if probe.expect == "refuse" and rc == 0 and not probe.interrupt:
            return Result(probe, "silent", "accepted (exit 0)", err, seconds)
        refused = probe.expect == "refuse" or (probe.expect == "any" and rc != 0)
        if refused and len(lines) > 3:
            return Result(probe, "unclear", f"{len(lines)} lines on stderr", err, seconds)
        missing = [w for w in probe.says if w.lower() not in err.lower()]
        if refused and rc != 0 and missing:
            return Result(probe, "vague", f"the message does not name {', '.join(missing)}", err, seconds)
        if probe.expect == "ok" and probe.check is not None:
            problem = probe.check(folder, out)
            if problem:
                return Result(probe, "wrong result", problem, err, seconds)
        # SIGKILL cannot be cleaned up after: its temporaries are the next run's to remove
        killed = probe.interrupt is not None and probe.interrupt[0] == signal.SIGKILL
        if temps and not killed:
            return Result(probe, "partial output", f"temporaries left: {temps[:3]}", err, seconds)
        if killed:
            new = [p for p in new if ".tmp-" not in p and ".old-" not in p]
        if refused and new and not (probe.interrupt and rc == 0):
            return Result(probe, "partial output", f"left {new[:3]}", err, seconds)
        if probe.then:
            r = subprocess.run(ABACUS + probe.then, cwd=folder, env=_env(probe.env), capture_output=True,
                               text=True, timeout=180)
            if r.returncode != 0 or "Traceback" in r.stderr:
                return Result(probe, "not resumable", f"the next run failed: {r.stderr.strip()[-200:]}",
                              err, seconds)
            temps = sorted(p for p in _listing(folder) if ".tmp-" in p or ".old-" in p)
            if temps:
                return Result(probe, "partial output", f"stale temporaries after the rerun: {temps[:3]}",
                              err, seconds)
        return Result(probe, "clean", "", err, seconds)
    except Exception as exc:  # the harness itself failed: report, do not hide
        return Result(probe, "harness error", f"{exc.__class__.__name__}: {exc}"[:300])
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(folder / "disk")], capture_output=True)
        for p in folder.rglob("*"):
            try:
                os.chmod(p, 0o755) if p.is_dir() else None
            except OSError:
                pass
        shutil.rmtree(box, ignore_errors=True)


def _current_layout(path: Path) -> bool:
    import xarray as xr

    from processing.base.dataset import ELEMENT_GROUP
    try:
        with xr.open_datatree(path) as t:
            t[ELEMENT_GROUP]
        return True
    except Exception:
        return False


def prepare():
    """A good 1-ping dataset the dataset probes damage, and a warm geometry cache."""
    (CACHE / "boxes").mkdir(parents=True, exist_ok=True)
    good = CACHE / "good.nc"
    if good.exists() and not _current_layout(good):
        good.unlink()                   # made by an older abacus: the probes damage today's layout
    if not good.exists():
        (CACHE / "s.yaml").write_text(BASE)
        subprocess.run(ABACUS + ["simulate", str(CACHE / "s.yaml"), "-o", str(good), "--overwrite"],
                       check=True, env=_env(), capture_output=True)
    # every damaged dataset the probes use, made here in the main thread, one at a time
    kinds = {content.kind for p in probes() for content in p.files.values()
             if callable(content) and hasattr(content, "kind")}
    for kind in sorted(kinds):
        target = _dataset_file(kind)
        target.unlink(missing_ok=True)
        _make_dataset(kind, target)


def run_all(classes=None, *, workers: int = 2) -> list[Result]:
    prepare()
    return run_probes([p for p in probes() if classes is None or p.cls in classes], workers=workers)


def run_probes(todo, *, workers: int = 2) -> list[Result]:
    """Run probes (two at a time, those that time themselves alone), in their order."""
    # interrupts and disk probes time themselves: run them alone, the rest two at a time
    timed = [p for p in todo if p.interrupt or p.tmpfs_mb]
    rest = [p for p in todo if p not in timed]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(run_probe, rest))
    results += [run_probe(p) for p in timed]
    order = {p.name + p.cls: i for i, p in enumerate(todo)}
    return sorted(results, key=lambda r: order[r.probe.name + r.probe.cls])


def report(results) -> str:
    classes = list(dict.fromkeys(r.probe.cls for r in results))
    verdicts = ["traceback", "hang", "partial output", "silent", "leak", "outside", "wrong exit",
                "unclear", "vague", "wrong result", "slow interrupt", "refused control", "not resumable",
                "harness error"]
    rows = []
    for c in classes:
        rs = [r for r in results if r.probe.cls == c]
        counts = {v: sum(r.verdict == v for r in rs) for v in verdicts}
        other = sum(counts.values()) - counts["traceback"] - counts["hang"] - counts["partial output"] - counts["silent"]
        rows.append(f"| {c} | {len(rs)} | {sum(r.verdict == 'clean' for r in rs)} | {counts['traceback']} | "
                    f"{counts['hang']} | {counts['partial output']} | {counts['silent']} | {other} |")
    total = len(results)
    clean = sum(r.verdict == "clean" for r in results)
    bad = [r for r in results if r.verdict != "clean"]
    text = [
        "# Reliability",
        "",
        "What `abacus` does with bad inputs, bad options, interrupts and full disks, regenerated by "
        "`python benchmarks/reliability.py` (one class: `--only CLASS`). Every probe runs the command "
        "line in a fresh folder. *Clean*: a refusal with a short message (at most 3 lines, no "
        "traceback, no echo of a file the user did not write) and the documented exit status, "
        "nothing left behind (no output, no temporary, nothing outside the folder) — or, for the "
        "controls and the resumable cases, a success. Interrupts must stop within 5 s.",
        "",
        f"Machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}. Generated "
        f"{_dt.date.today().isoformat()}. **{clean} of {total} probes clean.**",
        "",
        "| class | tried | clean | traceback | hang | partial output | silently accepted | other |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "## Exit statuses",
        "",
        "| status | meaning |", "|---|---|",
        "| 0 | done |", "| 1 | an internal error (a bug): one line, the traceback in a log file it names |",
        "| 2 | a bad scene, settings file, dataset, mesh or option: one line naming file, line, key and what is accepted |",
        "| 3 | refused up front: the estimated memory or output exceeds the limit (`--max-memory`, `ABACUS_MAX_MEMORY_GB`, free disk) |",
        "| 5 | the machine refused a write (disk full, permission): nothing half-written |",
        "| 130 / 143 | interrupted (SIGINT) / terminated (SIGTERM): temporaries removed, within 5 s |",
        "",
        "## Rules the probes hold the code to",
        "",
        "- Outputs are never replaced without `--overwrite`; a missing output folder is an error (create it); "
        "`abacus run` without `-o` writes `runs/<name>` with the scene's name reduced to letters, digits, "
        "`-`, `_` and `.`; `abacus experiment -o DIR` resumes the same experiment, refuses another one "
        "(its parts carry the experiment's identity, so even without a manifest) and refuses a folder of "
        "other files; `--restart` discards.",
        "- Everything is written to a hidden temporary next to its final name and renamed when complete "
        "(`processing/base/atomic.py`); a killed process' temporaries are removed by the next write to the same "
        "name; `abacus run` writes its numbers first and its figures after, each as a whole folder.",
        "- Scene files: YAML without anchors or aliases, at most 1 MB and 32 levels deep, regular files only; "
        "mesh and grid files only inside the scene's folder (`ABACUS_ALLOW_OUTSIDE_FILES=1` lifts it), at "
        "most 256 MB; no message quotes a file's contents.",
        "- Numbers: finite, within documented physical ranges (e.g. sound speed 1300–1800 m/s, f0 ≤ 10 MHz, "
        "bandwidth ≤ sampling rate); targets and the sonar must be in the water; nothing non-finite is "
        "written unless the variable's `nan_means` attribute says what it means.",
        "",
    ]
    if bad:
        text += ["## Probes that were not clean", "", "| class | probe | verdict | reason | stderr (last line) |",
                 "|---|---|---|---|---|"]
        for r in bad:
            last = (r.stderr.strip().splitlines() or [""])[-1].replace("|", "\\|")[:160]
            text.append(f"| {r.probe.cls} | {r.probe.name} | {r.verdict} | {r.reason.replace('|', '/')} | {last} |")
        text.append("")
    text += ["## Every probe", "", "| class | probe | verdict | seconds | message |", "|---|---|---|---|---|"]
    for r in results:
        last = (r.stderr.strip().splitlines() or [""])[-1].replace("|", "\\|")[:140]
        text.append(f"| {r.probe.cls} | {r.probe.name} | {r.verdict} | {r.seconds:.1f} | {last} |")
    return "\n".join(text) + "\n"


#: the classes the test suite runs whole (signals, full disks, memory limits, what a scene may
#: read); of every other class it runs the first two probes
SUITE_WHOLE = {"interrupts", "resources", "paths"}


def suite_probes() -> list[Probe]:
    """The probes ``tests/test_reliability.py`` runs (``--suite``)."""
    seen: dict = {}
    out = []
    for p in probes():
        if p.cls in SUITE_WHOLE or seen.get(p.cls, 0) < 2:
            out.append(p)
        seen[p.cls] = seen.get(p.cls, 0) + 1
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="probe classes to run")
    ap.add_argument("--list", action="store_true", help="list the probes and exit")
    ap.add_argument("--suite", action="store_true",
                    help="run the test suite's probes and print their verdicts as JSON (no report)")
    ap.add_argument("-o", "--out", default=str(ROOT / "docs" / "reliability.md"))
    args = ap.parse_args(argv)
    if args.list:
        for p in probes():
            print(f"{p.cls:22s} {p.name}")
        print(f"{len(probes())} probes")
        return 0
    if args.suite:
        import json
        prepare()
        results = run_probes(suite_probes())
        print(json.dumps([{"cls": r.probe.cls, "name": r.probe.name, "verdict": r.verdict,
                           "reason": r.reason, "stderr": r.stderr.strip()[-300:]} for r in results]))
        return 0
    results = run_all(set(args.only) if args.only else None)
    text = report(results)
    out = Path(args.out)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(text)
    tmp.replace(out)
    clean = sum(r.verdict == "clean" for r in results)
    print(f"{clean} of {len(results)} clean; wrote {out}")
    for r in results:
        if r.verdict != "clean":
            print(f"  {r.verdict:15s} {r.probe.cls}: {r.probe.name}: {r.reason}")
    return 0 if clean == len(results) else 1


if __name__ == "__main__":
    sys.exit(main())
