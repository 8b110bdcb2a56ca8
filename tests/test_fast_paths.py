"""Issue 31's shortcuts in the ray stage, each against the way it replaces: the caster that keeps
its still meshes' Embree scene when a sea moves, and the specular search limited to a fan."""
from __future__ import annotations

import numpy as np
import trimesh

from acoustics.paths.meshes import SceneMesh
from acoustics.paths.raycast import RayCaster
from acoustics.paths.specular import specular_points, vertex_normals


def _grid(z0, size, n, amp, seed):
    rng = np.random.default_rng(seed)
    x = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(x, x)
    Z = z0 + amp * np.sin(X / 1.3 + rng.uniform(0, 6)) * np.cos(Y / 1.7 + rng.uniform(0, 6))
    v = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    f = np.concatenate([np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])])
    return trimesh.Trimesh(v, f, process=False)


def _meshes(sea_z=-2.0, moving=True):
    floor = SceneMesh("floor", "boundary", "floor", _grid(20.0, 30.0, 41, 0.3, 1), None, "floor")
    sea = SceneMesh("sea", "boundary", "surface", _grid(sea_z, 30.0, 31, 0.4, 2), None, "sea",
                    surface=object() if moving else None)
    return [floor, sea]


def _rays(n=4000, seed=5):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return np.zeros((n, 3)), d


def test_split_caster_hits_what_one_scene_hits():
    # the floor in one Embree scene, the sea in another: the nearest hit over both is the hit
    # of a single scene of both (faces, float64 distances, occlusion)
    split = RayCaster(_meshes(moving=True))
    whole = RayCaster(_meshes(moving=False))
    assert len(split._parts) == 2 and len(whole._parts) == 1
    o, d = _rays()
    a, b = split.first_hit(o, d), whole.first_hit(o, d)
    assert a.hit.mean() > 0.5                       # both meshes are hit, most rays hit
    assert set(np.unique(a.mesh[a.hit])) == {0, 1}
    np.testing.assert_array_equal(a.face, b.face)
    np.testing.assert_array_equal(a.distance, b.distance)
    ends = np.random.default_rng(6).uniform(-10, 10, (3000, 3)) * [1, 1, 2.5]
    np.testing.assert_array_equal(split.occluded(np.zeros_like(ends), ends),
                                  whole.occluded(np.zeros_like(ends), ends))


def test_a_new_sea_keeps_the_still_meshes_scene():
    first = RayCaster(_meshes())
    floor = first.meshes[0]
    sea = SceneMesh("sea", "boundary", "surface", _grid(-2.5, 30.0, 31, 0.4, 3), None, "sea",
                    surface=object())
    first.first_hit(*_rays(seed=7))                       # rays that build its sea's scene
    again = RayCaster([floor, sea], previous=first)
    assert again._parts[0][0] is first._parts[0][0]      # the floor's BVH, not rebuilt
    o, d = _rays(seed=8)
    fresh = RayCaster([floor, SceneMesh("sea", "boundary", "surface", sea.mesh, None, "sea")])
    np.testing.assert_array_equal(again.first_hit(o, d).face, fresh.first_hit(o, d).face)
    assert again._parts[1][0] is not first._parts[1][0]
    # the same arrays as a caster made from nothing (the previous ones, the sea's rows anew)
    for name in ("vertices", "faces", "face_mesh", "face_normal", "face_plane"):
        np.testing.assert_array_equal(getattr(again, name), getattr(fresh, name))


def test_a_sea_no_ray_can_reach_is_never_built():
    # rays that stay below the sea (the sea at z = -2 ± 0.4, the rays at z >= 0) cannot hit
    # it: its scene is not built, and the hits and occlusion are those of a caster with it
    floor, sea = _meshes()
    lazy = RayCaster([floor, sea])
    whole = RayCaster(_meshes(moving=False))
    o, d = _rays(seed=11)
    d[:, 2] = np.abs(d[:, 2]) + 1.0                      # every ray heads down, to the floor
    d[:, :2] *= 0.3
    a, b = lazy.first_hit(o, d), whole.first_hit(o, d)
    ends = np.random.default_rng(12).uniform(-10, 10, (2000, 3)) * [1, 1, 0] + [0, 0, 15.0]
    blocked = lazy.occluded(np.zeros_like(ends), ends)
    assert lazy._parts[1][0] is None                     # never built
    assert a.hit.mean() > 0.8                            # the floor is hit
    np.testing.assert_array_equal(a.face, b.face)
    np.testing.assert_array_equal(a.distance, b.distance)
    np.testing.assert_array_equal(blocked, whole.occluded(np.zeros_like(ends), ends))
    # a ray up, to the sea: now it is built, and hit
    up = lazy.first_hit(np.zeros((1, 3)), np.array([[0.1, 0.0, -1.0]]))
    assert lazy._parts[1][0] is not None and up.mesh[0] == 1


def _az_el(points, origin):
    c = points - origin
    r = np.linalg.norm(c, axis=1)
    return np.arctan2(c[:, 0], c[:, 2]), np.arcsin(c[:, 1] / r)


def test_windowed_specular_search_finds_every_bounce_inside_its_window():
    # a wavy floor below, a source above it and targets around: the window keeps exactly the
    # bounce points of the full search that lie inside it (none of the others is invented)
    m = _grid(0.0, 30.0, 81, 0.3, 4)
    m.vertices[:, 2] *= -1                 # z down: the floor at +z, the source above at z = -12
    m.vertices[:, 2] += 12.0
    nrm = vertex_normals(m.vertices, m.faces)
    src = np.array([0.0, 0.0, 0.0])
    rng = np.random.default_rng(9)
    tgt = np.column_stack([rng.uniform(-8, 8, 60), rng.uniform(-8, 8, 60), rng.uniform(3, 9, 60)])
    S = np.broadcast_to(src, tgt.shape)
    ext = (-0.35, 0.35, -0.12, 0.12)
    full = specular_points(m.vertices, m.faces, nrm, S, tgt)
    win = specular_points(m.vertices, m.faces, nrm, S, tgt, window=(src, np.eye(3), ext))
    az, el = _az_el(full.point_m, src)
    inside = (az > ext[0] + 0.02) & (az < ext[1] - 0.02) & (el > ext[2] + 0.02) & (el < ext[3] - 0.02)
    assert inside.sum() >= 10 and (~inside).sum() >= 10
    got = {(int(p), round(float(x), 6)) for p, x in zip(win.pair, win.point_m[:, 0])}
    want = {(int(p), round(float(x), 6)) for p, x in zip(full.pair[inside], full.point_m[inside, 0])}
    assert want <= got
    az_w, el_w = _az_el(win.point_m, src)
    pad = 0.2                               # a block's angular size at these ranges
    assert np.all((az_w > ext[0] - pad) & (az_w < ext[1] + pad) & (el_w > ext[2] - pad) & (el_w < ext[3] + pad))
    assert len(win) < len(full)


def test_a_window_leaves_out_a_surface_near_its_origin_that_lies_outside_it():
    # a wavy sea 2 m above a source whose window looks down (30 deg wide): the sea's blocks near
    # the source subtend more than the window's margin, so their facets are windowed one by one
    # and none reaches in; the full search finds the sea's bounce points all the same
    m = _grid(-2.0, 30.0, 31, 0.2, 6)
    nrm = vertex_normals(m.vertices, m.faces)
    src = np.zeros(3)
    rng = np.random.default_rng(13)
    tgt = np.column_stack([rng.uniform(-6, 6, 40), rng.uniform(-6, 6, 40), rng.uniform(5, 12, 40)])
    S = np.broadcast_to(src, tgt.shape)
    ext = (-0.26, 0.26, -0.26, 0.26)        # about +z, straight down
    full = specular_points(m.vertices, m.faces, nrm, S, tgt)
    win = specular_points(m.vertices, m.faces, nrm, S, tgt, window=(src, np.eye(3), ext),
                          near_facets=True)
    az, el = _az_el(full.point_m, src)
    assert len(full) >= 20 and not np.any((np.abs(az) < 0.5) & (np.abs(el) < 0.5))
    assert len(win) == 0
    # by the blocks' spheres alone (the setting off) the near blocks let some of them in
    blocky = specular_points(m.vertices, m.faces, nrm, S, tgt, window=(src, np.eye(3), ext))
    assert 0 < len(blocky) < len(full)


ROUGH = """name: prepare
medium: {sound_speed_m_s: 1500}
pings: {count: 2}
targets: {points: [{position_m: [1.0, 0.5, 14.0]}, {position_m: [-1.5, 0.2, 12.0]},
                   {position_m: [0.4, -1.0, 16.0]}]}
boundaries:
  - {name: floor, role: floor,
     mesh: {shape: rough_floor, depth_m: 20.0, center_m: [0.0, 0.0], size_m: [16.0, 16.0],
            resolution_m: 0.5, rms_height_m: 0.1, correlation_length_m: 1.5, seed: 3},
     reflection: {model: rayleigh, density_kg_m3: 1900, sound_speed_m_s: 1700},
     scattering: {law: lambert, mu_db: -27}}
effects: {max_bounces: 1, reverberation: {enabled: true, rays_per_square_degree: 20}}
"""


def test_a_runs_preparation_changes_no_ping():
    # what a run makes once (the floor's BVH, its vertex normals and search blocks, the
    # reverberation fan) is made before the first ping, in rays_build: the pings are the same
    # bits as when each is made where it is first needed
    import warnings

    from acoustics.scene import SceneWarning, scene_from_text
    from acoustics.simulation.ping import simulate_ping
    from acoustics.simulation.setup import RunCache, make_setup
    from acoustics.simulation.stages import StageLog
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        setup = make_setup(scene_from_text(ROUGH))
    first, lazy = RunCache(setup), RunCache(setup)
    lazy.ray_scene.prepared = True                       # never prepared: made as needed
    log = StageLog()
    a = simulate_ping(setup, 0, cache=first, log=log)[0]
    b = simulate_ping(setup, 0, cache=lazy)[0]
    assert first.ray_scene.prepared and "rays_build" in log
    assert first.ray_scene._block_cache and len(lazy.ray_scene.last_specular) > 0
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(simulate_ping(setup, 1, cache=first)[0],
                                  simulate_ping(setup, 1, cache=lazy)[0])


def test_block_spheres_are_numpys_to_the_bit():
    # the compiled pass adds in numpy's order (np.add.reduceat: the first row plus the pairwise
    # sum of the rest), so a moving sea's blocks are those of the numpy expressions it replaces
    from acoustics.paths.specular_blocks import block_spheres
    rng = np.random.default_rng(21)
    at = np.concatenate([[0], np.cumsum(rng.choice([3, 24, 48, 300, 480], 60))]).astype(np.int64)
    pts = rng.normal(size=(at[-1], 3)) * [40.0, 30.0, 0.4] + [5.0, -3.0, 20.0]
    nrm = rng.normal(size=pts.shape) * [0.1, 0.1, 1.0]
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    centre, radius, axis, na = block_spheres(pts, nrm, at)
    counts = np.diff(at)
    owner = np.repeat(np.arange(counts.size), counts)
    want_c = np.add.reduceat(pts, at[:-1], axis=0) / counts[:, None]
    a = np.add.reduceat(nrm, at[:-1], axis=0)
    want_n = np.linalg.norm(a, axis=1)
    np.testing.assert_array_equal(centre, want_c)
    np.testing.assert_array_equal(radius, np.sqrt(np.maximum.reduceat(
        ((pts - want_c[owner]) ** 2).sum(axis=1), at[:-1])))
    np.testing.assert_array_equal(na, want_n)
    np.testing.assert_array_equal(axis, a / want_n[:, None])
