"""A generated floor streamed in tiles (acoustics/paths/tiles.py, effects.floor_tiles) is the
floor the same generator makes whole: the same vertices and normals bit for bit, the same ray
hits, blockages and specular points, the same pings — whatever the memory setting, which bounds
the tiles held at once."""
import dataclasses
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from acoustics.paths.meshes import SceneMesh
from acoustics.paths.raycast import RayCaster
from acoustics.paths.specular import specular_points, vertex_normals
from acoustics.paths.tiles import FloorTiles, TileCache, TileMemoryError

ROOT = Path(__file__).resolve().parents[1]


def _spec(**kw):
    base = dict(seed=7, resolution_m=0.25, size_m=(20.0, 12.0), center_m=(5.0, 0.0), rms_height_m=0.1,
                correlation_length_m=1.0, depth_m=30.0, slope=(-0.03, 0.01))
    base.update(kw)
    return SimpleNamespace(**base)


def _placement():
    # the floor 2 m below the sonar, turned 10° about x (a pose with a rotation)
    a = np.radians(10.0)
    p = np.eye(4)
    p[1:3, 1:3] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    p[:3, 3] = [0.0, 0.0, -28.0]
    return p


def _floors(memory_mb=0.5, tile_vertices=17):
    tiles = FloorTiles(_spec(), 3, _placement(), memory_mb=memory_mb, tile_vertices=tile_vertices)
    v, f = tiles.whole()
    return tiles, v, f


def test_tiles_are_the_whole_floor_bit_for_bit():
    floor, v, f = _floors()
    tiles = TileCache(floor)      # the run's: the floor holds no built tile
    n = vertex_normals(v, f)
    assert floor.n_tiles > 4 and floor.n_faces == f.shape[0]
    for k in range(floor.n_tiles):
        t = tiles.tile(k)
        i0, i1, j0, j1 = floor._window(k)
        rows = (np.arange(j0, j1)[:, None] * floor.nx + np.arange(i0, i1)[None, :]).ravel()
        assert np.array_equal(t.vertices, v[rows])
        assert np.array_equal(t.normals, n[rows])          # the halo: edges as the whole mesh's
    # the field's statistics: RMS height within its sampling error (≈ 100 correlation cells)
    h = floor.heights(0, floor.nx, 0, floor.ny)
    assert abs(h.std() / 0.1 - 1) < 0.2
    # built on demand, never more than the setting
    assert tiles.peak_cached_bytes <= tiles.memory_bytes
    assert tiles.builds == floor.n_tiles and len(tiles) < floor.n_tiles
    # a copy of the floor (a worker's) carries no built tile and builds the same ones
    import pickle
    copy = pickle.loads(pickle.dumps(floor))
    assert np.array_equal(TileCache(copy).tile(0).vertices, tiles.tile(0).vertices)


def _casters(memory_mb):
    tiles, v, f = _floors(memory_mb)
    box = trimesh.creation.box(extents=(2, 2, 2))
    box.apply_translation((3.0, 0.0, 1.0))
    target = SceneMesh("box", "target", "rigid", box, None, "t")
    whole = RayCaster([SceneMesh("f", "boundary", "floor", trimesh.Trimesh(v, f, process=False), None, "k"),
                       target])
    tiled = RayCaster([SceneMesh("f", "boundary", "floor", tiles, None, "k"), target])
    return whole, tiled, tiled.tile_cache(0)


@pytest.mark.parametrize("memory_mb", [0.4, 100.0])
def test_the_caster_over_tiles_hits_what_the_whole_floor_hits(memory_mb):
    whole, tiled, tiles = _casters(memory_mb)
    assert tiled.eps_m == whole.eps_m
    rng = np.random.default_rng(1)
    n = 5000
    d = np.column_stack([rng.uniform(-0.7, 0.7, n), rng.uniform(-0.4, 0.4, n), np.ones(n)])
    for limit in (None, 2.75):
        a = whole.first_hit(np.zeros((n, 3)), d, max_distance_m=limit)
        b = tiled.first_hit(np.zeros((n, 3)), d, max_distance_m=limit)
        assert 0 < a.hit.sum() < n or limit is None
        for x, y in ((a.hit, b.hit), (a.mesh, b.mesh), (a.distance, b.distance), (a.point, b.point),
                     (a.normal, b.normal)):
            assert np.array_equal(x, y)
    # segments through the floor and short of it
    ends = a.point * rng.uniform(0.9, 1.1, (n, 1))
    starts = np.broadcast_to([0.0, 0.0, 0.5], ends.shape)
    blocked = tiled.occluded(starts, ends)
    assert 0 < blocked.sum() < n
    assert np.array_equal(blocked, whole.occluded(starts, ends))
    assert tiles.peak_cached_bytes <= tiles.memory_bytes


def test_specular_points_over_tiles_are_the_whole_floors():
    tiles, v, f = _floors()
    rng = np.random.default_rng(2)
    s = np.zeros((60, 3))
    p = np.column_stack([rng.uniform(-5, 15, 60), rng.uniform(-5, 5, 60), rng.uniform(-3, 1.0, 60)])
    a = specular_points(v, f, vertex_normals(v, f), s, p)
    b = tiles.specular_points(s, p)
    assert len(a) > 30 and len(a) == len(b)
    assert np.array_equal(a.pair, b.pair)
    assert np.allclose(a.point_m, b.point_m, rtol=0, atol=1e-9)
    assert np.allclose(a.divergence, b.divergence, rtol=1e-9, atol=0)
    # with a fan (effects.specular.beam_level_db) blocks of facets are admitted whole, so the
    # two groupings differ only by paths outside the fan
    fan = (-0.5, 0.5, -0.3, 0.3)
    window = (np.zeros(3), np.eye(3), fan)
    a = specular_points(v, f, vertex_normals(v, f), s, p, window=window)
    b = tiles.specular_points(s, p, window=window)

    def unmatched(x, y):
        """Points of x with no point of y of the same pair within 1 µm."""
        return [q for i, q in zip(x.pair, x.point_m)
                if not np.any((y.pair == i) & (np.linalg.norm(y.point_m - q, axis=1) < 1e-6))]

    def in_fan(q):
        return (fan[0] <= np.arctan2(q[0], q[2]) <= fan[1]
                and fan[2] <= np.arcsin(q[1] / np.linalg.norm(q)) <= fan[3])

    assert sum(in_fan(q) for q in b.point_m) >= 3
    assert not [q for q in unmatched(a, b) + unmatched(b, a) if in_fan(q)]


def test_a_memory_setting_that_holds_no_tile_is_refused_in_one_line():
    with pytest.raises(TileMemoryError) as err:
        FloorTiles(_spec(), 3, _placement(), memory_mb=0.01, tile_vertices=65, key="boundaries[0].mesh")
    msg = str(err.value)
    assert "effects.floor_tiles.memory_mb" in msg and "boundaries[0].mesh" in msg and "\n" not in msg


def _survey(memory_mb, fish=20):
    from acoustics.scene import scene_from_text
    text = (ROOT / "scenes" / "hard_survey.yaml").read_text()
    text = text.replace("count: 1000", f"count: {fish}").replace("resolution_m: 0.25", "resolution_m: 1.0")
    text = text.replace("  reverberation: {enabled: true, rays_per_square_degree: 100}\n",
                        "  reverberation: {enabled: true, rays_per_square_degree: 100}\n"
                        f"  floor_tiles: {{enabled: true, memory_mb: {memory_mb}, tile_vertices: 17}}\n")
    text = text.replace("  specular: {beam_level_db: -20.0}\n", "")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return scene_from_text(text)


def test_a_ping_over_tiles_is_the_ping_over_the_whole_floor():
    from acoustics.simulation.ping import simulate_ping
    from acoustics.simulation.setup import RunCache, make_setup
    scene = _survey(0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        setup = make_setup(scene)
        tiled, whole = RunCache(setup), RunCache(setup)
        rs = whole.ray_scene
        v, f = rs.meshes[0].mesh.whole()
        rs.meshes[0] = dataclasses.replace(rs.meshes[0], mesh=trimesh.Trimesh(v, f, process=False))
        rs.caster = RayCaster(rs.meshes, threads=rs.caster.threads)
        a = simulate_ping(setup, 1, cache=tiled)[0]
        b = simulate_ping(setup, 1, cache=whole)[0]
    ft = tiled.ray_scene.caster.tile_cache(0)   # the run's tiles, not the setup's floor's
    assert ft.builds > ft.floor.n_tiles         # tiles were evicted and built again
    assert ft.peak_cached_bytes <= 0.5e6
    assert np.max(np.abs(b)) > 0 and np.array_equal(a, b)


def test_the_setting_is_validated():
    from acoustics.scene import SceneError, scene_from_text
    text = (ROOT / "scenes" / "default.yaml").read_text()
    with pytest.raises(SceneError) as err:
        scene_from_text(text + "\neffects:\n  floor_tiles: {enabled: true, memory_mb: -5}\n"
                        if "\neffects:" not in text else
                        text.replace("\neffects:\n", "\neffects:\n  floor_tiles: {enabled: true, memory_mb: -5}\n", 1))
    assert "floor_tiles.memory_mb" in str(err.value)


def test_the_estimate_counts_the_setting_not_the_facets():
    from acoustics.scene import scene_from_text
    from acoustics.simulation.budget import estimate_scene
    text = (ROOT / "scenes" / "hard_survey.yaml").read_text().replace("resolution_m: 0.25", "resolution_m: 0.03")
    line = "  reverberation: {enabled: true, rays_per_square_degree: 100}\n"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = estimate_scene(scene_from_text(text), pings=1)
        tiled = estimate_scene(scene_from_text(text.replace(
            line, line + "  floor_tiles: {enabled: true, memory_mb: 1500}\n")), pings=1)
    # 10⁷ facets: held whole at least 1 kB each (measured 1.2, docs/performance.md); in tiles the
    # setting and one tile's build
    assert whole.memory_bytes > 1e10
    floor = dict(tiled.terms)["floor tiles"]
    assert 1.5e9 <= floor <= 1.5e9 + 0.1e9
    assert tiled.largest_driver().key == "effects.floor_tiles.memory_mb"
