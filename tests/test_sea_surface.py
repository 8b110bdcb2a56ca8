"""A wavy sea: wave spectra, the moving surface, and specular paths off curved meshes.

References: the image method in the flat limit (delay < 1 ns, level < 0.1 dB); the mirror
equation of a cylinder (closed form: the stationary point is constructed, the level is
R/√((r₁+r₂)(r₁+r₂ ± 2r₁r₂/(ρ cos θ)))); Fermat's principle solved in one dimension for a
travelling sinusoid (scipy's brentq on the analytic surface) at every ping time; Parseval and the
textbook significant wave heights of the spectra; the dispersion relation of gravity waves.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from acoustics import SceneWarning
from acoustics.paths.meshes import _grid_mesh
from acoustics.paths.sea_surface import (GRAVITY_M_S2, jonswap, pierson_moskowitz,
                                         significant_wave_height_m, swell, wind_sea)
from acoustics.paths.specular import specular_points, vertex_normals
from acoustics.scene import scene_from_text
from acoustics.simulation.run import make_setup, simulate
from acoustics.simulation.ping import simulate_ping
from acoustics.simulation.setup import RunCache
from acoustics.synthesis.arrivals import arrivals
from processing.base.dataset import stage_seconds


def text_scene(text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return scene_from_text(text)


# ------------------------------------------------------------------ spectra and the sea
def test_pierson_moskowitz_significant_height_is_the_textbook_value():
    """H_s = 0.21 U₁₉.₅²/g (Stewart 2008, eq. 16.32) — from the integral of the spectrum."""
    for u10 in (5.0, 10.0, 15.0):
        hs = significant_wave_height_m(lambda w: pierson_moskowitz(w, u10))
        assert hs == pytest.approx(0.21 * (1.026 * u10) ** 2 / GRAVITY_M_S2, rel=0.01)


def test_jonswap_peaks_where_hasselmann_puts_it():
    u, f = 10.0, 20e3
    w = np.linspace(0.2, 5.0, 20001)
    wp = 22.0 * (GRAVITY_M_S2**2 / (u * f)) ** (1 / 3)
    assert w[np.argmax(jonswap(w, u, f))] == pytest.approx(wp, rel=1e-3)


def test_wind_sea_mean_square_is_its_spectrum_and_seeded():
    """The sampled surface's mean square over its period equals Σ a²/2 (no opposite pair of
    components: Parseval holds exactly), and the grid holds the spectrum's variance but for
    the reported unresolved share; the same seed gives the same sea."""
    s = wind_sea(wind_speed_m_s=10.0, fetch_m=20e3, size_m=(60.0, 60.0), resolution_m=0.25, seed=4)
    v, n = s.grid(7.0)
    eta = -v[:, 2].reshape(s.y_m.size, s.x_m.size)[:-1, :-1]
    assert eta.mean() == pytest.approx(0.0, abs=1e-12)
    assert np.mean(eta**2) == pytest.approx(s.variance_m2, rel=1e-9)
    hs_spec = significant_wave_height_m(lambda w: jonswap(w, 10.0, 20e3))
    assert 4 * np.sqrt(s.variance_m2) == pytest.approx(
        hs_spec * np.sqrt(1 - s.unresolved_variance_fraction), rel=1e-3)
    assert s.unresolved_variance_fraction < 0.05       # a 60 m grid holds a 21 m peak wave
    assert np.all(np.abs(np.linalg.norm(n, axis=1) - 1) < 1e-12)
    again = wind_sea(wind_speed_m_s=10.0, fetch_m=20e3, size_m=(60.0, 60.0), resolution_m=0.25, seed=4)
    assert np.array_equal(again.grid(7.0)[0], v)
    other = wind_sea(wind_speed_m_s=10.0, fetch_m=20e3, size_m=(60.0, 60.0), resolution_m=0.25, seed=5)
    assert not np.allclose(other.grid(7.0)[0], v)


def test_wind_sea_grid_by_fft_equals_the_sum_of_its_waves():
    s = wind_sea(wind_speed_m_s=8.0, size_m=(20.0, 12.0), resolution_m=0.5, seed=2)
    v, n = s.grid(3.3)
    pick = np.random.default_rng(0).integers(0, v.shape[0], 50)
    eta, ex, ey = s.elevation(v[pick, 0], v[pick, 1], 3.3)
    np.testing.assert_allclose(-v[pick, 2], eta, atol=1e-12)
    nd = np.column_stack([-ex, -ey, -np.ones_like(ex)])
    np.testing.assert_allclose(n[pick], nd / np.linalg.norm(nd, axis=1)[:, None], atol=1e-12)


@pytest.mark.parametrize("depth", [None, 5.0])
def test_a_swell_crest_travels_at_the_phase_speed_of_gravity_waves(depth):
    """c = ω/k with ω² = g k tanh(k d) (deep: c = √(g/k))."""
    lam = 20.0
    s = swell(components=[(0.5, lam, 0.0, 0.0)], size_m=(40.0, 2.0), resolution_m=0.01,
              depth_m=depth)
    k = 2 * np.pi / lam
    c = np.sqrt(GRAVITY_M_S2 / k * (1.0 if depth is None else np.tanh(k * depth)))
    x = np.linspace(-5, 15, 200001)
    for t in (0.0, 1.0, 2.5):
        eta, _, _ = s.elevation(x, np.zeros_like(x), t)
        crest = x[np.argmax(eta)]
        assert crest == pytest.approx(c * t, abs=2e-4)


# ------------------------------------------------------------ specular points: references
def _flat_grid(size=40.0, step=0.5, z=0.0):
    x = np.arange(-size / 2, size / 2 + step / 2, step)
    return _grid_mesh(x, x, np.full((x.size, x.size), z))


def test_specular_points_on_a_flat_mesh_are_the_image_sources():
    """A finely faceted plane (the finder, not the image method): every path has the image's
    length (< 1 ns two-way at 1500 m/s), its point and divergence 1 (< 0.1 dB)."""
    m = _flat_grid()
    rng = np.random.default_rng(3)
    s = np.column_stack([rng.uniform(-8, 8, (40, 2)), rng.uniform(0.5, 8, 40)])
    p = np.column_stack([rng.uniform(-8, 8, (40, 2)), rng.uniform(0.5, 8, 40)])
    sp = specular_points(m.vertices, m.faces, vertex_normals(m.vertices, m.faces), s, p)
    assert np.array_equal(sp.pair, np.arange(40))                 # one path each
    img = p * [1, 1, -1]
    length = np.linalg.norm(img - s, axis=1)
    assert np.abs(sp.source_range_m + sp.receiver_range_m - length).max() / 1500 < 1e-9
    np.testing.assert_allclose(sp.image_m, img, atol=1e-9)
    assert np.abs(20 * np.log10(np.abs(sp.divergence))).max() < 0.1
    assert np.all(sp.signature == 2) and not sp.capped.any()


def _cylinder(rho, convex, half_width=4.0, step=0.025):
    """z = ±(√(ρ² − x²) − ρ): a cylinder of radius ρ along y, convex (bulging to +z) or concave
    seen from z > 0; top at z = 0."""
    x = np.arange(-half_width, half_width + step / 2, step)
    y = np.linspace(-8.0, 8.0, 65)
    zc = np.sqrt(rho**2 - x**2) - rho
    return _grid_mesh(x, y, np.tile(zc if convex else -zc, (y.size, 1)))


@pytest.mark.parametrize("convex", [True, False])
@pytest.mark.parametrize("alpha_deg,theta_deg,r1,r2", [(0.0, 20.0, 5.0, 7.0), (12.0, 35.0, 6.0, 9.0),
                                                      (-8.0, 60.0, 4.0, 3.0)])
def test_cylinder_stationary_point_and_level_are_the_mirror_equation(convex, alpha_deg, theta_deg,
                                                                     r1, r2):
    """The bounce point is where it was built (closed form) and the level is the mirror
    equation's, within 0.5 dB (facets of 2.5 cm on a 5-m cylinder)."""
    rho = 5.0
    m = _cylinder(rho, convex)
    a = np.radians(alpha_deg)
    sgn = 1.0 if convex else -1.0
    x0 = np.array([rho * np.sin(a), 0.0, sgn * (rho * np.cos(a) - rho)])
    n = np.array([np.sin(a) * sgn, 0.0, np.cos(a)])
    n /= np.linalg.norm(n)
    th = np.radians(theta_deg)

    def rot(v, ang):
        return np.array([v[0] * np.cos(ang) + v[2] * np.sin(ang), 0.0,
                         -v[0] * np.sin(ang) + v[2] * np.cos(ang)])

    s, p = x0 + r1 * rot(n, th), x0 + r2 * rot(n, -th)
    sp = specular_points(m.vertices, m.faces, vertex_normals(m.vertices, m.faces), s[None], p[None])
    near = np.linalg.norm(sp.point_m - x0, axis=1) < 0.05
    assert near.sum() == 1
    j = int(np.flatnonzero(near)[0])
    assert np.linalg.norm(sp.point_m[j] - x0) < 2e-3           # m (facet sag ≤ 16 µm)
    total = r1 + r2
    focus = total + sgn * 2 * r1 * r2 / (rho * np.cos(th))
    expect = total / np.sqrt(total * abs(focus))
    assert abs(20 * np.log10(abs(sp.divergence[j]) / expect)) < 0.5
    # an ordinary mirror point, or a saddle past the in-plane focus (phase +90°)
    assert sp.signature[j] == (2 if focus > 0 else 0)


def _sinusoid_paths(s_pt, p_pt, amp, lam, omega, t, x_lo, x_hi, level):
    """Fermat in one dimension on z = level − a cos(kx − ωt): every stationary x, its path
    length, and the geometrical-optics level (mirror equation with the local curvature)."""
    k = 2 * np.pi / lam

    def z(x):
        return level - amp * np.cos(k * x - omega * t)

    def dz(x):
        return amp * k * np.sin(k * x - omega * t)

    def d2z(x):
        return amp * k * k * np.cos(k * x - omega * t)

    def dphi(x):
        out = 0.0
        for q in (s_pt, p_pt):
            out += ((x - q[0]) + (z(x) - q[2]) * dz(x)) / np.hypot(x - q[0], z(x) - q[2])
        return out

    xs = np.linspace(x_lo, x_hi, 4001)
    f = np.array([dphi(x) for x in xs])
    roots = [brentq(dphi, xs[i], xs[i + 1], xtol=1e-12) for i in np.flatnonzero(f[:-1] * f[1:] < 0)]
    out = []
    for x in roots:
        X = np.array([x, 0.0, z(x)])
        r1, r2 = np.linalg.norm(X - s_pt), np.linalg.norm(X - p_pt)
        nrm = np.array([dz(x), 0.0, -1.0]) / np.hypot(1, dz(x))       # up, towards the water
        cos_t = abs((X - s_pt) @ nrm) / r1
        kappa = d2z(x) / (1 + dz(x) ** 2) ** 1.5    # >0: a crest (z is depth), concave seen from below: focuses
        total = r1 + r2
        focus = total - 2 * r1 * r2 * kappa / cos_t
        out.append((X, total, total / np.sqrt(total * abs(focus))))
    return out


@pytest.mark.parametrize("exact", [True, False])
def test_travelling_sinusoid_bounce_points_follow_fermat_at_every_ping(exact):
    """A swell of one sinusoid (0.3 m, 12 m) moving by the dispersion relation: at each ping
    time every stationary point of the 1-D Fermat problem is found. Refined on the exact
    surface (the default): path length within 1 µm, level within 0.01 dB; on the mesh alone:
    path length within the facets' sag bound, level within 0.5 dB."""
    lam, amp, step = 12.0, 0.3, 0.05
    scene = text_scene(f"""
name: swell ghost
sonar:
  pose: {{position_m: [0, 0, 4], boresight: [1, 0, 0], receiver_axis: [0, 1, 0]}}
medium: {{sound_speed_m_s: 1500.0}}
boundaries:
  - name: sea surface
    role: surface
    mesh: {{shape: swell, center_m: [12, 0], size_m: [36, 6], resolution_m: {step},
           waves: [{{amplitude_m: {amp}, wavelength_m: {lam}}}]}}
effects: {{max_bounces: 1, specular: {{exact_surface: {str(exact).lower()}}}}}
pings: {{count: 6, interval_s: 0.7}}
""")
    setup = make_setup(scene)
    rs = RunCache(setup).ray_scene
    pose = setup.sonar.pose
    target_w = np.array([20.0, 0.0, 2.0])
    target = pose.to_sonar(target_w[None])
    omega = np.sqrt(GRAVITY_M_S2 * 2 * np.pi / lam)
    k = 2 * np.pi / lam
    sag = step**2 * amp * k * k / 8                      # flat facet vs the curve (m)
    tol_m, tol_db = (1e-6, 0.01) if exact else (4 * sag + 1e-6, 0.5)
    seen_shift = []
    for ping in range(6):
        t = ping * 0.7
        rs.advance(t)
        tx_c = pose.to_world(rs.tx_center[None])[0]
        expect = _sinusoid_paths(tx_c, target_w, amp, lam, omega, t, 0.5, 23.5, 0.0)
        got_t, got_img, got_c, _ = rs.specular_legs(rs.tx_center, target)
        _, _, sp, ok = rs.last_specular[-1]
        pts = pose.to_world(sp.point_m[ok])
        assert len(pts) == len(expect) >= 1
        for X, total, level in expect:
            j = int(np.argmin(np.linalg.norm(pts - X, axis=1)))
            assert np.linalg.norm(pts[j] - X) < 0.01
            got_total = (sp.source_range_m + sp.receiver_range_m)[ok][j]
            assert abs(got_total - total) < tol_m
            assert abs(20 * np.log10(abs(sp.divergence[ok][j]) / level)) < tol_db
        # the ghost's unfolded image is where the moving surface puts it
        main = int(np.argmax(np.abs(got_c)))
        seen_shift.append(np.linalg.norm(got_img[main] - rs.tx_center))
    # and it moves: the swell changes the ghost's path by a good part of the wave height
    assert np.ptp(seen_shift) > 0.1 * amp


# ----------------------------------------------------------- through the simulation
_FLAT = """
name: flat sea
sonar:
  pose: {{position_m: [0, 0, 5], boresight: [1, 0, 0], receiver_axis: [0, 1, 0]}}
medium: {{sound_speed_m_s: 1500.0}}
targets:
  points:
    - {{frame: world, position_m: [20.0, 0.5, 3.0]}}
boundaries:
  - name: sea surface
    role: surface
    mesh: {mesh}
effects: {{max_bounces: 1}}
"""


def test_flat_limit_through_the_simulation_equals_the_image_method():
    """The same sea as a plane (image sources) and as a swell of zero height (specular
    points on a 0.25-m mesh): same paths, delays within 1 ns, levels within 0.1 dB, per
    element."""
    image = make_setup(text_scene(_FLAT.format(
        mesh="{shape: plane, center_m: [15, 0, 0], normal: [0, 0, 1], size_m: [40, 20]}")))
    curved = make_setup(text_scene(_FLAT.format(
        mesh="{shape: swell, center_m: [15, 0], size_m: [40, 20], resolution_m: 0.25, "
             "waves: [{amplitude_m: 0.0, wavelength_m: 10.0}]}")))
    rs_image, rs_curved = RunCache(image).ray_scene, RunCache(curved).ray_scene
    assert rs_image.planes and not rs_curved.planes and rs_curved.curved
    p = image.sonar.pose.to_sonar(np.array([[20.0, 0.5, 3.0]]))
    a = rs_image.multipath(p, np.ones(1), 1)
    b = rs_curved.multipath(p, np.ones(1), 1)
    assert len(a) == len(b) == 3
    ta, aa = arrivals(image.model, a.p_tx, a.strength, receive_positions_m=a.p_rx)
    tb, ab = arrivals(curved.model, b.p_tx, b.strength, receive_positions_m=b.p_rx)
    for j in range(3):
        i = int(np.argmin([np.abs(tb[m] - ta[j]).max() for m in range(3)]))
        assert np.abs(tb[i] - ta[j]).max() < 1e-9
        assert np.abs(20 * np.log10(np.abs(ab[i] / aa[j]))).max() < 0.1
        assert np.abs(np.angle(ab[i] / aa[j])).max() < 0.01


def test_only_a_moving_sea_runs_the_sea_stage_and_the_run_records_it():
    still = simulate(text_scene(_FLAT.format(
        mesh="{shape: plane, center_m: [15, 0, 0], normal: [0, 0, 1], size_m: [40, 20]}")))
    assert "sea_surface" not in list(stage_seconds(still))
    wavy = text_scene(_FLAT.format(
        mesh="{shape: swell, center_m: [15, 0], size_m: [40, 20], resolution_m: 0.5, "
             "waves: [{amplitude_m: 0.2, wavelength_m: 10.0}]}"))
    tree = simulate(wavy.model_copy(update={"pings": wavy.pings.model_copy(update={"count": 2})}))
    stages = list(stage_seconds(tree))
    assert "sea_surface" in stages and "multipath" in stages


def test_same_seed_same_sea_whatever_the_ping_order():
    scene = text_scene(_FLAT.format(
        mesh="{shape: wind_sea, wind_speed_m_s: 10, fetch_km: 20, center_m: [15, 0], "
             "size_m: [40, 20], resolution_m: 0.5}"))
    a = make_setup(scene)
    b = make_setup(scene)
    ca, cb = RunCache(a), RunCache(b)
    xa = [simulate_ping(a, p, cache=ca)[0] for p in (0, 1, 2)]
    xb = [simulate_ping(b, p, cache=cb)[0] for p in (2, 0, 1)]
    assert np.array_equal(xa[0], xb[1]) and np.array_equal(xa[2], xb[0])
    assert not np.array_equal(xa[0], xa[1])           # the sea moved between pings


# ------------------------------------------------------------------ hard cases
def test_a_caustic_is_capped_and_counted_not_infinite():
    """Source and receiver at the centre of a concave cylinder (r₁ = r₂ = ρ: the mirror
    equation's focus term 2r − 2r²/ρ vanishes): geometrical optics diverges; the path is held
    at the focusing limit and flagged. At ρ/2 the same mirror gives √2 (no cap)."""
    rho = 5.0
    m = _cylinder(rho, convex=False, step=0.02)
    nv = vertex_normals(m.vertices, m.faces)
    f = np.array([[0.0, 0.0, rho]])
    sp = specular_points(m.vertices, m.faces, nv, f, f, focusing_limit_db=20.0)
    assert len(sp) >= 1 and np.all(np.isfinite(sp.divergence))
    assert np.abs(sp.divergence).max() <= 10.0 + 1e-12 and sp.capped.any()
    half = np.array([[0.0, 0.0, rho / 2]])
    sp = specular_points(m.vertices, m.faces, nv, half, half, focusing_limit_db=20.0)
    assert abs(abs(sp.divergence[0]) - np.sqrt(2)) < 0.01 and not sp.capped.any()


def test_grazing_on_surface_and_empty_cases_stay_finite():
    m = _flat_grid(size=10.0, step=0.5)
    nv = vertex_normals(m.vertices, m.faces)
    # source and receiver on the surface itself, and grazing at 0.01°
    s = np.array([[0.0, 0.0, 0.0], [-4.0, 0.0, 1e-4], [1.0, 1.0, 2.0]])
    p = np.array([[2.0, 0.0, 1.0], [4.0, 0.0, 1e-4], [1.0, 1.0, 0.0]])
    sp = specular_points(m.vertices, m.faces, nv, s, p)
    for field in ("point_m", "image_m", "divergence", "cos_incidence"):
        assert np.all(np.isfinite(getattr(sp, field)))
    assert not np.isin([0, 2], sp.pair).any()          # no bounce for a point on the surface
    # a receiver above the surface (the other side) has no specular path
    sp = specular_points(m.vertices, m.faces, nv, [[0, 0, 1.0]], [[3, 0, -1.0]])
    assert len(sp) == 0
    assert len(specular_points(m.vertices, m.faces, nv, np.zeros((0, 3)), np.zeros((0, 3)))) == 0


def test_paths_are_found_on_a_mesh_of_a_hundred_thousand_facets():
    s = wind_sea(wind_speed_m_s=10.0, fetch_m=20e3, size_m=(56.0, 56.0), resolution_m=0.25, seed=1)
    v, n = s.grid(0.0)
    m = _grid_mesh(s.x_m, s.y_m, v[:, 2].reshape(s.y_m.size, s.x_m.size))
    assert len(m.faces) >= 100_000
    rng = np.random.default_rng(0)
    tgt = np.column_stack([rng.uniform(5, 20, 20), rng.uniform(-3, 3, 20), rng.uniform(2, 6, 20)])
    sp = specular_points(m.vertices, m.faces, n, np.broadcast_to([0.0, 0.0, 4.0], tgt.shape), tgt)
    assert set(sp.pair) == set(range(20))             # every target sees the sea somewhere
    assert np.all(np.isfinite(sp.divergence)) and np.all(sp.cos_incidence > 0)


def test_ghosts_in_the_images_follow_the_moving_surface():
    """End to end on scenes/swell_ghost.yaml (3 pings): behind the direct echo, the image peaks
    along the target's beam sit at the ranges of the analytic bounce points of the travelling
    swell (1-D Fermat by brentq; one bounce on one leg, and on both), within a quarter of the
    range resolution c/2B, and they move between pings by more than that resolution."""
    import processing
    from acoustics import load_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "swell_ghost.yaml")
    pings = (0, 5, 8)
    scene = scene.model_copy(update={"pings": scene.pings.model_copy(update={"count": 9})})
    images = processing.images_of(processing.image(simulate(scene)))
    c = scene.medium.sound_speed_m_s
    resolution = c / (2 * scene.signal.bandwidth_hz)
    wave = scene.boundaries[0].mesh.waves[0]
    k = 2 * np.pi / wave.wavelength_m
    omega = np.sqrt(GRAVITY_M_S2 * k)
    sonar, target = np.array([0.0, 0.0, 4.0]), np.array([20.0, 0.0, 2.0])
    direct = np.linalg.norm(target - sonar)
    beam = int(np.argmin(np.abs(images.beam_angle_rad)))
    rng = images.range_m
    seen = []
    for p in pings:
        paths = _sinusoid_paths(sonar, target, wave.amplitude_m, wave.wavelength_m, omega,
                                p * scene.pings.interval_s, 1.0, 19.5, 0.0)
        bounce = min(total for _, total, _ in paths)
        col = np.abs(images.image[p, 0][:, beam])
        for expect in ((direct + bounce) / 2, bounce):
            near = np.abs(rng - expect) < resolution
            i = int(np.flatnonzero(near)[np.argmax(col[near])])
            a, b, cc = np.log(col[i - 1:i + 2])
            peak = rng[i] + 0.5 * (a - cc) / (a - 2 * b + cc) * (rng[1] - rng[0])
            assert abs(peak - expect) < resolution / 4
        seen.append(bounce)
    assert np.ptp(seen) > resolution


def test_a_moving_sea_reverberates_from_where_its_facets_are_each_ping():
    """Surface reverberation on a swell: the rays' hits lie on the surface of the ping's time
    (to float precision of the mesh), they move between pings, and nothing runs when the sea
    does not scatter."""
    text = """
name: surface reverberation
sonar:
  pose: {{position_m: [0, 0, 3], boresight: [0.5, 0, -0.2], receiver_axis: [0, 1, 0]}}
medium: {{sound_speed_m_s: 1500.0}}
boundaries:
  - name: sea surface
    role: surface
    mesh: {{shape: swell, center_m: [12, 0], size_m: [30, 20], resolution_m: 0.25,
           waves: [{{amplitude_m: 0.4, wavelength_m: 15.0}}]}}
    scattering: {scattering}
effects: {{reverberation: {{enabled: true, rays_per_square_degree: 4}}}}
pings: {{count: 2, interval_s: 1.0}}
"""
    scene = text_scene(text.format(scattering="{law: lambert, mu_db: -30.0}"))
    setup = make_setup(scene)
    rs = RunCache(setup).ray_scene
    pose = setup.sonar.pose
    hits = []
    for ping in (0, 1):
        rs.advance(ping * 1.0)
        vs = rs.reverberation(setup, ping, scene.seed)
        assert len(vs) > 100 and np.all(np.isfinite(vs.strength))
        w = pose.to_world(vs.p_tx)
        z, *_ = rs.meshes[0].surface.height(w[:, 0], w[:, 1], ping * 1.0)
        # on the facets: within the sag of 0.25-m facets on a 0.4-m, 15-m wave
        sag = 0.25**2 * 0.4 * (2 * np.pi / 15) ** 2 / 8 * 2
        assert np.abs(w[:, 2] - z).max() < sag + 1e-6
        hits.append(w)
    assert np.abs(hits[0][:, 2].mean() - hits[1][:, 2].mean()) > 1e-3 or not np.allclose(
        hits[0][:50], hits[1][:50])
    quiet = simulate(text_scene(text.format(scattering="null")))
    assert "reverberation" not in list(stage_seconds(quiet))


@pytest.mark.parametrize("name", ["pelagic_wind_sea", "swell_ghost", "pelagic_floor_rock",
                                  "calibration_sphere"])
def test_the_resource_estimate_counts_the_faces_a_mesh_builds(name):
    """The budget's face count (memory estimate before any work) bounds the built mesh's faces
    within 10 % (it used to read a key shapes do not have and counted none)."""
    from acoustics import load_scene
    from acoustics.simulation.budget import mesh_faces
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / f"{name}.yaml")
    setup = make_setup(scene)
    specs = [*scene.boundaries, *scene.targets.meshes]
    built = {sm.name: len(sm.mesh.faces) for sm in setup.rays.meshes}
    for spec in specs:
        est = mesh_faces(spec)
        assert built[spec.name] <= est <= 1.1 * built[spec.name] + 12


def _path_lengths(rs, vs):
    tx_c, rx_c = rs.centers()
    return (np.linalg.norm(vs.p_tx - tx_c, axis=1) + np.linalg.norm(vs.p_rx - rx_c, axis=1))


@pytest.mark.parametrize("mesh", [
    "{shape: plane, center_m: [15, 0, 0], normal: [0, 0, 1], size_m: [40, 20]}",
    "{shape: swell, center_m: [15, 0], size_m: [40, 20], resolution_m: 0.25, "
    "waves: [{amplitude_m: 0.3, wavelength_m: 12.0, direction_deg: 20.0}]}"])
def test_multipath_doppler_is_the_rate_of_change_of_each_path(mesh):
    """The rate each path's length changes (its Doppler shift is −f0/c times it) — from the
    target's velocity along its legs, the platform's, and the moving sea's vertical velocity at
    the bounce points — equals the central difference of the path lengths with the target, the
    sonar and the sea moved ±1 ms (to 1 mm/s)."""
    setup = make_setup(text_scene(_FLAT.format(mesh=mesh)))
    rs = RunCache(setup).ray_scene
    p0 = setup.sonar.pose.to_sonar(np.array([[20.0, 0.5, 3.0]]))
    v_t = np.array([[0.4, -0.3, 0.6]])          # sonar-frame axes (m/s)
    v_s = np.array([0.2, 0.1, -0.5])
    t0, dt = 1.0, 1e-3
    rs.advance(t0)
    vs = rs.multipath(p0, np.ones(1), 1, velocities_m_s=v_t, sonar_velocity_m_s=v_s)
    rate = vs.rate_m_s.copy()
    assert rate.size == len(vs) >= 3

    def lengths(sign):
        from acoustics.frames import Pose
        rs.advance(t0 + sign * dt)
        # the sonar moving by v_s·dt is the scene moving by −v_s·dt around it
        view = Pose(sign * dt * v_s, np.eye(3))
        # the target's built-frame position moves by v_t·dt; seen from the moved sonar
        out = rs.multipath(p0 + sign * dt * (v_t - v_s), np.ones(1), 1, view)
        tx_c, rx_c = rs.centers(view)
        return (np.linalg.norm(view.to_world(out.p_tx) - tx_c, axis=1)
                + np.linalg.norm(view.to_world(out.p_rx) - rx_c, axis=1))

    after, before = lengths(+1), lengths(-1)
    assert after.size == before.size == rate.size
    fd = (after - before) / (2 * dt)
    np.testing.assert_allclose(np.sort(rate), np.sort(fd), atol=1e-3)


def test_a_ping_gives_its_surface_paths_the_doppler_of_the_moving_sea(monkeypatch):
    """With effects.doppler on, a still target under a swell: its direct echo has no shift and
    each surface path has −f0/c times its rate of change of length (the sea's motion)."""
    import acoustics.simulation.ping as ping_mod
    scene = text_scene(_FLAT.format(
        mesh="{shape: swell, center_m: [15, 0], size_m: [40, 20], resolution_m: 0.25, "
             "waves: [{amplitude_m: 0.3, wavelength_m: 12.0}]}").replace(
        "effects: {max_bounces: 1}", "effects: {max_bounces: 1, doppler: true}"))
    setup = make_setup(scene)
    cache = RunCache(setup)
    seen, paths = {}, []
    real, real_multipath = ping_mod.synthesize, cache.ray_scene.multipath

    def spy(*args, **kw):
        seen.update(kw)
        return real(*args, **kw)

    def multipath_spy(*args, **kw):
        paths.append(real_multipath(*args, **kw))
        return paths[-1]

    monkeypatch.setattr(ping_mod, "synthesize", spy)
    monkeypatch.setattr(cache.ray_scene, "multipath", multipath_spy)
    simulate_ping(setup, 2, cache=cache)
    rate = paths[0].rate_m_s
    f0, c = scene.signal.center_frequency_hz, scene.medium.sound_speed_m_s
    assert seen["doppler_hz"][0] == 0.0                      # the still target, direct
    np.testing.assert_allclose(seen["doppler_hz"][1:1 + rate.size], -rate * f0 / c)
    assert np.abs(seen["doppler_hz"][1:]).max() > 10.0        # Hz: the sea moves ~0.5 m/s


def test_the_block_cull_finds_exactly_what_the_exhaustive_search_finds():
    """Skipping blocks of facets whose normal cone cannot meet the legs' bisector is a bound,
    not an approximation: on a wind sea (100 random targets, with grazing and near-surface
    ones) and on both cylinders the same bounce points come out."""
    s = wind_sea(wind_speed_m_s=10.0, fetch_m=20e3, size_m=(40.0, 30.0), resolution_m=0.25, seed=9,
                 center_m=(18.0, 0.0))
    v, n = s.grid(2.0)
    m = _grid_mesh(s.x_m, s.y_m, v[:, 2].reshape(s.y_m.size, s.x_m.size))
    rng = np.random.default_rng(11)
    tgt = np.column_stack([rng.uniform(2, 36, 100), rng.uniform(-12, 12, 100),
                           rng.uniform(0.3, 10, 100)])
    src = np.broadcast_to([0.0, 0.0, 4.0], tgt.shape)
    cases = [(m.vertices, m.faces, n, src, tgt)]
    for convex in (True, False):
        c = _cylinder(5.0, convex)
        pts = np.column_stack([rng.uniform(-3, 3, 30), rng.uniform(-5, 5, 30), rng.uniform(0.5, 6, 30)])
        cases.append((c.vertices, c.faces, vertex_normals(c.vertices, c.faces),
                      np.broadcast_to([0.5, 0.0, 4.0], pts.shape), pts))

    def key(sp):
        return sorted(zip(sp.pair.tolist(), np.round(sp.point_m, 7).tolist()))

    for args in cases:
        fast = specular_points(*args, cull=True)
        full = specular_points(*args, cull=False)
        assert len(full) > 0 and key(fast) == key(full)


def test_the_tree_search_finds_every_glint_of_a_rough_floor():
    """On a rough floor (rms slope ~0.1, many glints per pair) the tight block bound, the tree
    over the blocks and the targets' groups leave out no bounce point of the exhaustive search:
    a school of targets seen from two sources (so that the groups split where the source
    changes), the same points to 1e-7 m, the pairs in any order."""
    rng = np.random.default_rng(5)
    x, y = np.arange(0.0, 16.01, 0.25), np.arange(-6.0, 6.01, 0.25)
    X, Y = np.meshgrid(x, y)
    z = np.zeros_like(X)
    for _ in range(30):                   # random smooth bumps, 1-3 m across
        k = rng.uniform(1.5, 5.0) * np.array([np.cos(a := rng.uniform(0, np.pi)), np.sin(a)])
        z += rng.normal(0, 0.02) * np.cos(k[0] * X + k[1] * Y + rng.uniform(0, 2 * np.pi))
    z -= 8.0
    m = _grid_mesh(x, y, z)
    nrm = vertex_normals(m.vertices, m.faces)
    school = np.array([8.0, 0.0, -4.0]) + rng.normal(0, 0.8, (40, 3))
    src = np.repeat([[0.0, 0.0, 0.0], [0.3, 0.1, 0.0]], 20, axis=0)
    order = rng.permutation(40)
    fast = specular_points(m.vertices, m.faces, nrm, src[order], school[order], cull=True)
    full = specular_points(m.vertices, m.faces, nrm, src, school, cull=False)
    assert np.bincount(full.pair).max() >= 3       # a rough floor: several glints per pair

    def key(sp, pairs):
        return sorted(zip(pairs[sp.pair].tolist(), np.round(sp.point_m, 7).tolist()))

    assert len(full) > 40 and key(fast, order) == key(full, np.arange(40))


def test_the_sea_bound_finds_what_the_exhaustive_search_finds_and_no_tighter_one_would(monkeypatch):
    """On a moving sea whose bounce points are refined on the exact height field, the blocks
    are skipped by the tight bound grown by the field's curvature (how far a refined point may
    lie from its facet's): a bound, so the same points as every facet (a steep two-wave swell on
    a coarse 1 m mesh, 200 targets). The check can fail: the same bound with its spheres cut to
    a tenth loses bounce points."""
    import acoustics.paths.specular_field as field_bound
    import acoustics.paths.specular_search as search
    s = swell(components=[(0.4, 12.0, 20.0, 0.0), (0.1, 5.0, -40.0, 30.0)], size_m=(40.0, 30.0),
              resolution_m=1.0, center_m=(18.0, 0.0))
    v, n = s.grid(3.0)
    m = _grid_mesh(s.x_m, s.y_m, v[:, 2].reshape(s.y_m.size, s.x_m.size))
    k = np.linalg.norm(s.k_m, axis=1)
    a = np.abs(s.amplitude_m)
    field = (lambda x, y: s.height(x, y, 3.0), np.eye(4))
    bounded = field + ((float(a @ k), float(a @ (k * k))),)
    rng = np.random.default_rng(3)
    tgt = np.column_stack([rng.uniform(2, 36, 200), rng.uniform(-12, 12, 200),
                           rng.uniform(0.5, 10, 200)])
    src = np.broadcast_to([0.0, 0.0, 2.0], tgt.shape)

    def key(sp):
        return sorted(zip(sp.pair.tolist(), np.round(sp.point_m, 7).tolist()))

    full = specular_points(m.vertices, m.faces, n, src, tgt, height_field=field, cull=False)
    fast = specular_points(m.vertices, m.faces, n, src, tgt, height_field=bounded)
    assert len(full) > 300 and key(fast) == key(full)
    grown = field_bound.height_field_blocks
    monkeypatch.setattr(search, "height_field_blocks",
                        lambda *args: (grown(*args)[0] * 0.1, grown(*args)[1]))
    search._FIELD_CACHE.clear()
    too_tight = specular_points(m.vertices, m.faces, n, src, tgt, height_field=bounded)
    search._FIELD_CACHE.clear()
    assert len(too_tight) < len(full)
