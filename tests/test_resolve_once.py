"""Resolve once: the Scene is read by ``make_setup`` (and ``simulate`` above it), never in the
ping loop; the frozen setup is the loop's only input and no run changes it; what a run fills
lives in its ``RunCache``; every path kind carries its own rate column (no side channel)."""
from __future__ import annotations

import ast
import copy
import dataclasses
import hashlib
import re
import warnings

import numpy as np
import pytest
import trimesh
from pydantic import BaseModel

import acoustics
from acoustics.scene import SceneWarning, scene_from_text
from acoustics.simulation.ping import simulate_ping
from acoustics.simulation.setup import RunCache, make_setup

from .conftest import ROOT

#: the modules the ping loop runs in: below ``simulation/run.py``, none may see a Scene
BELOW_RUN = sorted(
    [ROOT / "acoustics" / "simulation" / f"{m}.py" for m in ("ping", "arrival_table", "stages", "setup")]
    + list((ROOT / "acoustics" / "targets").glob("*.py"))
    + list((ROOT / "acoustics" / "paths").glob("*.py"))
    + list((ROOT / "acoustics" / "synthesis").glob("*.py"))
    + [ROOT / "acoustics" / "sonar" / "levels.py"])


def _may_read_the_scene(path, func) -> bool:
    """The resolve step in setup.py: ``make_setup`` and its ``resolve_*`` helpers."""
    return path.name == "setup.py" and (func.name == "make_setup"
                                        or func.name.lstrip("_").startswith("resolve"))


def _scene_uses(path):
    """'line: what' for every parameter named or annotated ``scene``/``Scene``, every use of a
    name ``scene`` and every import of the scene schema outside the resolve step."""
    tree = ast.parse(path.read_text())
    allowed = set()
    for node in ast.walk(tree):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        if _may_read_the_scene(path, node):
            allowed |= {id(n) for n in ast.walk(node)}
        elif any(isinstance(n, ast.Name) and n.id == "scene" and isinstance(n.ctx, ast.Store)
                 for n in ast.walk(node)):
            # a local of its own (Embree's scene in raycast.py), not a Scene passed down
            allowed |= {id(n) for n in ast.walk(node) if isinstance(n, ast.Name)}
    out = []
    for node in ast.walk(tree):
        if id(node) in allowed:
            continue
        if isinstance(node, ast.arg):
            ann = ast.unparse(node.annotation) if node.annotation is not None else ""
            if node.arg.lower() == "scene" or re.search(r"\bScene\b", ann):
                out.append(f"{node.lineno}: parameter {node.arg}: {ann}")
        elif isinstance(node, ast.Name) and node.id in ("scene", "Scene"):
            out.append(f"{node.lineno}: name {node.id}")
        elif isinstance(node, ast.ImportFrom) and node.module is not None and (
                node.module == "acoustics.scene.schema" or (
                    node.module == "acoustics.scene"
                    and {"Scene", "load_scene", "scene_from_text"} & {a.name for a in node.names})):
            out.append(f"{node.lineno}: from {node.module} import ...")
        elif isinstance(node, ast.Import) and any(a.name == "acoustics.scene.schema" for a in node.names):
            out.append(f"{node.lineno}: import acoustics.scene.schema")
    return out


def test_no_scene_below_the_run():
    assert len(BELOW_RUN) > 20
    found = {str(p.relative_to(ROOT)): u for p in BELOW_RUN if (u := _scene_uses(p))}
    assert not found, f"modules below simulation/run.py that see a Scene: {found}"


def test_the_scene_check_finds_a_scene_parameter(tmp_path):
    """The check above has teeth: a function taking ``scene`` (as ping.py did) is found."""
    bad = tmp_path / "ping.py"
    bad.write_text("def simulate_ping(scene, setup, ping):\n    return scene.seed\n")
    assert len(_scene_uses(bad)) == 2


def test_no_side_channel_for_path_rates():
    """Each path kind carries its rate of change of length in its own scatterers
    (``VirtualScatterers.rate_m_s``): no attribute like ``last_path_rate_m_s`` carries it
    from one call to the next."""
    pattern = re.compile(r"\blast_\w*(rate|doppler|velocit)\w*", re.I)
    hits = [f"{p.relative_to(ROOT)}:{i}" for p in (ROOT / "acoustics").rglob("*.py")
            for i, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert not hits


# ------------------------------------------------------------------ behaviour
#: every stage that keeps state between pings: a rolling platform heard at arrival, a moving
#: point target and swimming fish with swimbladders (Doppler), a swell that moves and
#: reverberates, a floor that reflects, a mesh target hung from the sonar (the ray scene is
#: rebuilt per pose), arrivals, noise and the ADC
BUSY = """
name: busy
seed: 11
sonar:
  pose: {position_m: [0, 0, 5.0], boresight: [1, 0, 0.14], receiver_axis: [0, 1, 0]}
  motion: {kind: series, series: {time_s: [0, 4], roll_deg: [0, 3], pitch_deg: [0, -1],
           yaw_deg: [0, 4], heave_m: [0, 0.3]}}
medium: {sound_speed_m_s: 1500.0}
sampling: {samples: 1200, adc: {quantize: true}}
noise: {enabled: true}
targets:
  points:
    - {frame: world, position_m: [14.0, 0.4, 5.0], velocity_m_s: [0.5, 0.2, 0.0]}
    - {range_m: 12.0, azimuth_deg: -3.0, elevation_deg: -7.0, random_phase: true}
  populations:
    - {kind: uniform_cuboid, frame: world, x_m: [12, 16], y_m: [-1, 1], z_m: [4, 6], count: 4,
       redraw: false, swim: {speed_m_s: 0.8, heading_deg: 30},
       backscatter: {model: swimbladder, length_m: 0.06, width_m: 0.01, subdivisions: 3}}
  meshes:
    - {name: ball, frame: sonar, mesh: {shape: sphere, center_m: [0.0, 0.0, 10.0], radius_m: 0.1}}
boundaries:
  - name: sea
    role: surface
    mesh: {shape: swell, center_m: [12, 0], size_m: [24, 8], resolution_m: 0.5,
           waves: [{amplitude_m: 0.2, wavelength_m: 10.0}]}
    scattering: {law: lambert, mu_db: -30.0}
  - {name: floor, role: floor, mesh: {shape: plane, center_m: [12, 0, 6.5], normal: [0, 0, -1],
     size_m: [30, 12]}, reflection: {model: constant, coefficient: 0.5},
     scattering: {law: lambert, mu_db: -27.0}}
effects:
  max_bounces: 1
  doppler: true
  stop_and_hop: false
  reverberation: {enabled: true, rays_per_square_degree: 0.5}
  arrivals: {enabled: true, floor_db: null}
pings: {count: 3, interval_s: 0.5}
"""


def _busy():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return scene_from_text(BUSY)


def _fingerprint(obj) -> str:
    """A digest of everything an object holds, down to array bytes: dataclasses field by field,
    other objects by their attributes (private ones too), meshes by vertices and faces (not
    trimesh's own lazily filled cache of derived values)."""
    h = hashlib.sha256()
    seen = {}       # id -> the object, kept alive so that a temporary's id is never reused

    def walk(x):
        if isinstance(x, (str, bytes, int, float, complex, bool, type(None))):
            h.update(repr(x).encode())
            return
        if id(x) in seen:
            h.update(b"<seen>")
            return
        seen[id(x)] = x
        h.update(type(x).__qualname__.encode())
        if isinstance(x, np.ndarray):
            h.update(str((x.dtype, x.shape)).encode() + np.ascontiguousarray(x).tobytes())
        elif isinstance(x, trimesh.Trimesh):
            walk(np.asarray(x.vertices))
            walk(np.asarray(x.faces))
        elif isinstance(x, BaseModel):
            h.update(x.model_dump_json().encode())
        elif dataclasses.is_dataclass(x):
            for f in dataclasses.fields(x):
                h.update(f.name.encode())
                walk(getattr(x, f.name))
            walk({k: v for k, v in vars(x).items()
                  if k not in {f.name for f in dataclasses.fields(x)}} if hasattr(x, "__dict__") else None)
        elif isinstance(x, dict):
            for k in sorted(x, key=repr):
                h.update(repr(k).encode())
                walk(x[k])
        elif isinstance(x, (list, tuple, set, frozenset)):
            for v in (sorted(x, key=repr) if isinstance(x, (set, frozenset)) else x):
                walk(v)
        elif callable(x) and not hasattr(x, "__dict__"):
            h.update(repr(x).encode())
        elif hasattr(x, "__dict__"):
            walk(vars(x))
        else:
            h.update(repr(x).encode())

    walk(obj)
    return h.hexdigest()


class _Poisoned:
    """A stand-in for the Scene and its sections: any use of it fails the test."""

    def __init__(self, what):
        object.__setattr__(self, "_what", what)

    def __getattr__(self, name):
        raise AssertionError(f"the ping loop read {self._what}.{name}")

    def __deepcopy__(self, memo):
        return self


def _frozen_all_the_way(x, path="setup", seen=None):
    """Every dataclass the setup holds is frozen (a setter raises)."""
    seen = set() if seen is None else seen
    if id(x) in seen or not dataclasses.is_dataclass(x) or isinstance(x, type):
        return
    seen.add(id(x))
    assert x.__dataclass_params__.frozen, f"{path} ({type(x).__name__}) is not frozen"
    for f in dataclasses.fields(x):
        v = getattr(x, f.name)
        for i, item in enumerate(v if isinstance(v, tuple) else (v,)):
            _frozen_all_the_way(item, f"{path}.{f.name}", seen)


def test_the_setup_is_frozen_and_a_run_leaves_it_unchanged():
    scene = _busy()
    setup = make_setup(scene)
    _frozen_all_the_way(setup)
    with pytest.raises(dataclasses.FrozenInstanceError):
        setup.seed = 3
    before = _fingerprint(setup)
    cache, tables = RunCache(setup), []
    rays_before = dict(cache.ray_scene.caster.rays_cast)
    for p in range(3):
        simulate_ping(setup, p, cache=cache, arrivals=tables)
    assert _fingerprint(setup) == before
    # the run's state went where it belongs: the cache's ray scene moved the sea, cast rays
    # and was rebuilt for the moving sonar (the sphere rides with it, the sea does not)
    last, view = cache.ray_scene_at(setup.pose_at(2))
    assert last is not cache.ray_scene and view is None and last.time_s == 2 * 0.5
    assert last.caster.rays_cast is cache.ray_scene.caster.rays_cast       # one count per run
    assert sum(last.caster.rays_cast.values()) > sum(rays_before.values())
    seqs = {str(s) for t in tables for s in t["sequence"]}
    assert len(tables) == 3 and "T" in seqs and "M" in seqs and "RF" in seqs
    assert any("S" in s.split("-") for s in seqs) and any("F" in s.split("-") for s in seqs)


def test_the_fingerprint_sees_a_change_deep_in_the_setup():
    """The comparison above has teeth: one vertex of one mesh moved by 1 µm changes it."""
    setup = make_setup(_busy())
    other = copy.deepcopy(setup)
    assert _fingerprint(other) == _fingerprint(setup)
    other.rays.meshes[0].mesh.vertices[0, 0] += 1e-6
    assert _fingerprint(other) != _fingerprint(setup)


def test_pings_from_a_setup_without_its_scene_equal_the_run():
    """The setup, copied with the Scene and each of its sections replaced by an object that
    fails on any use, simulates the same samples, bit for bit, as ``acoustics.simulate``."""
    scene = _busy()
    tree = acoustics.simulate(scene, pings=2)
    setup = make_setup(scene)
    memo = {id(scene): _Poisoned("scene")}
    for name in ("sonar", "signal", "sampling", "medium", "noise", "targets", "pings", "effects"):
        memo[id(getattr(scene, name))] = _Poisoned(f"scene.{name}")
    alone = copy.deepcopy(setup, memo)
    del setup
    cache = RunCache(alone)
    bg = tree["Sonar/Beam_group1"]
    got_r, got_i = bg["backscatter_r"].values, bg["backscatter_i"].values
    assert np.abs(got_r).max() > 0
    for i, p in enumerate(range(2)):
        x, clipped, targets = simulate_ping(alone, p, cache=cache)
        np.testing.assert_array_equal(x.real.T.astype(np.float32), got_r[0, i])
        np.testing.assert_array_equal(x.imag.T.astype(np.float32), got_i[0, i])
    assert len(targets) == 6


# ------------------------------------------------------------------ a floor in tiles
#: a small rough floor streamed in tiles whose memory setting holds fewer tiles than the floor
#: has (tiles are evicted and built again), under a sonar that rolls, with a target that echoes
#: on it, reverberation and a specular search over it
TILED = """
name: tiled
seed: 5
sonar:
  pose: {position_m: [0, 0, 2.0], boresight: [0.866, 0, 0.5], receiver_axis: [0, 1, 0]}
  motion: {kind: series, series: {time_s: [0, 4], roll_deg: [0, 3], pitch_deg: [0, -1]}}
medium: {sound_speed_m_s: 1500.0}
sampling: {samples: 1200}
targets:
  points:
    - {frame: world, position_m: [12.0, 0.5, 8.0]}
boundaries:
  - name: floor
    role: floor
    mesh: {shape: rough_floor, depth_m: 10.0, center_m: [12.0, 0.0], size_m: [24.0, 12.0],
           resolution_m: 0.25, rms_height_m: 0.05, correlation_length_m: 1.0, slope: [-0.02, 0.0],
           seed: 4}
    scattering: {law: lambert, mu_db: -27.0}
    reflection: {model: constant, coefficient: 0.5}
effects:
  max_bounces: 1
  reverberation: {enabled: true, rays_per_square_degree: 0.5}
  arrivals: {enabled: true, floor_db: null}
  floor_tiles: {enabled: true, memory_mb: 2.0, tile_vertices: 33}
pings: {count: 2, interval_s: 0.5}
"""


def _tiled_setup():
    from acoustics.paths.tiles import is_tiled
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        setup = make_setup(scene_from_text(TILED))
    floor = setup.rays.meshes[0].mesh
    assert is_tiled(floor)
    return setup, floor


def test_a_tiled_floor_leaves_the_setup_unchanged_and_two_runs_agree():
    """The built tiles of a floor in tiles are the run's (its caster's TileCache), not the
    frozen setup's: two runs from one setup leave its digest as it was, hold their own tiles,
    and give the same samples bit for bit."""
    setup, floor = _tiled_setup()
    before = _fingerprint(setup)
    runs, caches = [], []
    for _ in range(2):
        cache, tables = RunCache(setup), []
        runs.append([simulate_ping(setup, p, cache=cache, arrivals=tables)[0] for p in range(2)])
        assert _fingerprint(setup) == before
        # the floor was reached (echoes off it) and its tiles held by the run, within the setting
        seqs = {str(s) for t in tables for s in t["sequence"]}
        assert any("F" in s.split("-") for s in seqs)
        tiles = cache.ray_scene.caster.tile_cache(0)
        assert tiles.floor is floor and tiles.builds > 0
        assert 0 < tiles.peak_cached_bytes <= tiles.memory_bytes == 2.0e6
        assert len(tiles) < floor.n_tiles < tiles.builds      # tiles evicted and built again
        caches.append(tiles)
    assert caches[0] is not caches[1]
    assert not {id(t) for t in caches[0].tiles.values()} & {id(t) for t in caches[1].tiles.values()}
    assert np.abs(runs[0][0]).max() > 0
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)


def test_the_fingerprint_sees_tiles_kept_in_the_floor():
    """The digest covers the tiled floor: a built tile kept on the floor object (where the
    tiles lived before the run's TileCache) changes it."""
    setup, floor = _tiled_setup()
    before = _fingerprint(setup)
    floor.held = {0: floor.build(0)}
    try:
        assert _fingerprint(setup) != before
    finally:
        del floor.held
    assert _fingerprint(setup) == before
