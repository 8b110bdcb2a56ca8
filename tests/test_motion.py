"""Scenes in motion: targets that swim, schools, a platform that rolls and pitches."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import acoustics
import processing
from acoustics.scene import SceneWarning, scene_from_text

QUIET = "name: motion\nmedium: {sound_speed_m_s: 1530}\n"


def scene(text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return scene_from_text(QUIET + text)


def truth(tree):
    gt = tree["Vendor_specific"].ds
    return {k: gt[k].values for k in gt.data_vars}


# ------------------------------------------------------------------ targets that move
def test_a_moving_point_is_where_its_velocity_takes_it():
    """x(t_p) = x(0) + v t_p exactly, t_p = p x interval."""
    sc = scene("pings: {interval_s: 0.5}\ntargets:\n  points:\n"
               "    - {frame: world, position_m: [0.3, -2.0, 20.0], velocity_m_s: [0.1, 0.8, -0.05]}\n")
    t = truth(acoustics.simulate(sc, pings=range(12)))
    p = np.arange(12) * 0.5
    expected = np.array([0.3, -2.0, 20.0]) + p[:, None] * np.array([0.1, 0.8, -0.05])
    got = np.stack([t["target_world_x"], t["target_world_y"], t["target_world_z"]], -1)
    np.testing.assert_allclose(got, expected, atol=1e-12)
    assert np.all(t["target_id"] == 0)


SCHOOL = """pings: {interval_s: 1.0}
targets:
  populations:
    - kind: school
      center_m: [0.0, 0.0, 20.0]
      semi_axes_m: [3.0, 2.0, 1.0]
      heading_deg: 30
      count: 40
      nearest_neighbour_m: 0.3
      redraw: false
      swim: {speed_m_s: 0.8, speed_sd_m_s: 0.2, heading_deg: 30, polarisation: 0.9,
             turn_sd_deg_per_s: 20, vertical_sd_m_s: 0.02, substeps: 1}
"""


def test_positions_after_n_pings_are_the_integrated_motion():
    """Each fish keeps its identity, and its displacement from one ping to the next is its
    velocity times the interval (the velocity is constant within a step): after N pings the
    position is x(0) plus the sum of those steps."""
    t = truth(acoustics.simulate(scene(SCHOOL), pings=range(8)))
    n = 40
    ids = t["target_id"].reshape(8, n)
    assert np.all(ids == ids[0]) and len(set(ids[0])) == n
    pos = np.stack([t["target_world_x"], t["target_world_y"], t["target_world_z"]], -1).reshape(8, n, 3)
    vel = np.stack([t["target_velocity_world_x"], t["target_velocity_world_y"],
                    t["target_velocity_world_z"]], -1).reshape(8, n, 3)
    integrated = pos[0] + np.cumsum(vel[:-1] * 1.0, axis=0)
    np.testing.assert_allclose(pos[1:], integrated, atol=1e-9)
    speed = np.linalg.norm(vel[..., :2], axis=-1)
    assert np.allclose(speed, speed[0])                       # speeds persist, headings turn
    heading = np.arctan2(vel[..., 1], vel[..., 0])
    assert np.std(np.diff(np.unwrap(heading, axis=0), axis=0)) == pytest.approx(math.radians(20), rel=0.3)


def test_a_school_turning_together_keeps_its_polarisation():
    """Turning on their own, 40 fish at 20° per √s lose polarisation as exp(−σ²t/2) (0.9 → 0.15
    after 30 s); turning together they keep every heading difference, so the mean resultant
    length is the same at every ping."""
    def resultant(together):
        sc = scene(SCHOOL.replace("substeps: 1", f"substeps: 1, turn_together: {str(together).lower()}"))
        from acoustics.simulation.setup import make_setup
        from acoustics.targets.draw import draw_targets
        setup = make_setup(sc)
        out = []
        for p in (0, 30):
            v = draw_targets(setup.targets, p, setup.pose_at(p)).velocity_world_m_s
            out.append(np.arctan2(v[:, 1], v[:, 0]))
        return out
    h0, h30 = resultant(True)
    np.testing.assert_allclose(np.angle(np.exp(1j * (h30 - h0))), np.angle(np.exp(1j * (h30 - h0)))[0],
                               atol=1e-9)                       # one turn for all
    h0, h30 = resultant(False)
    r0, r30 = (abs(np.mean(np.exp(1j * h))) for h in (h0, h30))
    # 40 nearly random headings: a resultant length of about 0.14 from chance alone
    assert r30 == pytest.approx(r0 * math.exp(-math.radians(20) ** 2 * 30 / 2), abs=0.2)
    assert r30 < r0 - 0.15


def test_a_ping_alone_is_the_same_ping_of_a_run():
    """Ping independence survives motion: ping 6 alone puts every fish where a full run does."""
    sc = scene(SCHOOL)
    full = truth(acoustics.simulate(sc, pings=range(7)))
    alone = truth(acoustics.simulate(sc, pings=[6]))
    k = full["target_ping_index"] == 6
    for key in ("target_world_x", "target_world_y", "target_world_z", "target_id"):
        np.testing.assert_array_equal(alone[key], full[key][k])


def test_straight_swimming_with_substeps_is_exact():
    """Without turning the velocity never changes: x(t_p) = x(0) + v t_p whatever the
    sub-steps, and ping 37 (third block of the cached track) alone equals the same ping after
    pings 0–40 were computed."""
    from acoustics.simulation.setup import make_setup
    from acoustics.targets import motion
    from acoustics.targets.draw import draw_targets
    sc = scene(SCHOOL.replace("turn_sd_deg_per_s: 20", "turn_sd_deg_per_s: 0")
               .replace("vertical_sd_m_s: 0.02", "vertical_sd_m_s: 0").replace("substeps: 1", "substeps: 4")
               .replace("interval_s: 1.0", "interval_s: 0.7"))
    setup = make_setup(sc)
    motion._TRACKS.clear()
    alone = draw_targets(setup.targets, 37, setup.pose_at(37))
    motion._TRACKS.clear()
    first = draw_targets(setup.targets, 0, setup.pose_at(0))
    for p in range(1, 41):
        draw_targets(setup.targets, p, setup.pose_at(p))
    again = draw_targets(setup.targets, 37, setup.pose_at(37))
    np.testing.assert_array_equal(alone.position_world_m, again.position_world_m)
    np.testing.assert_allclose(again.position_world_m,
                               first.position_world_m + first.velocity_world_m_s * 37 * 0.7, atol=1e-9)


def test_swimming_needs_persistent_fish():
    with pytest.raises(acoustics.SceneError, match="redraw: false"):
        scene("targets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [-1,1], y_m: [-1,1], "
              "z_m: [15,16], count: 3, swim: {speed_m_s: 1}}\n")


def test_swimmers_stay_in_the_water():
    sc = scene("targets:\n  populations:\n    - {kind: school, center_m: [0,0,0.5], semi_axes_m: [1,1,0.3], "
               "count: 20, redraw: false, swim: {speed_m_s: 0.1, vertical_sd_m_s: 0.5}}\n")
    t = truth(acoustics.simulate(sc, pings=range(10)))
    assert np.all(t["target_world_z"] >= 0)


# ------------------------------------------------------------------ the platform
def _detected_angles(sc):
    tree = processing.count(acoustics.simulate(sc), {"detect": {"method": "fraction_of_peak",
                                                                "fraction": 0.5}})
    det = processing.detections_of(tree)
    out = []
    for p in range(tree["Processing/Counts"].sizes["ping_time"]):
        k = det["ping"].values == p
        i = int(np.argmax(det["amplitude"].values[k]))
        out.append((float(det["azimuth_rad"].values[k][i]), float(det["elevation_rad"].values[k][i]),
                    np.array([det[f"world_{a}_m"].values[k][i] for a in "xyz"])))
    return out


def test_platform_roll_moves_an_on_axis_target_by_the_roll_angle():
    """Mounted looking down, receiver athwartships: rolling starboard-down by 3° turns the
    receiver axis down and the boresight to port, so a target fixed in the world below the sonar
    appears at azimuth +3° (x_s = 20 sin 3°, z_s = 20 cos 3°); its world position is unchanged."""
    sc = scene("pings: {count: 2}\nsonar: {motion: {kind: series, series: {time_s: [0, 1], "
               "roll_deg: [0, 3]}}}\ntargets:\n  points:\n    - {frame: world, position_m: [0, 0, 20]}\n")
    (az0, _, w0), (az1, _, w1) = _detected_angles(sc)
    assert math.degrees(az0) == pytest.approx(0.0, abs=0.05)
    assert math.degrees(az1) == pytest.approx(3.0, abs=0.05)
    np.testing.assert_allclose(w1, [0, 0, 20], atol=0.03)          # located in the world, again
    np.testing.assert_allclose(w0, w1, atol=0.03)


def test_platform_pitch_moves_the_target_in_interferometric_elevation():
    """Pitching bow-up by 0.3° puts the same target at elevation +0.3° (y_s = 20 sin 0.3°), inside
    the 0.86° transmit beam, measured by interferometry."""
    sc = scene("pings: {count: 2}\nsonar: {motion: {kind: series, series: {time_s: [0, 1], "
               "pitch_deg: [0, 0.3]}}}\ntargets:\n  points:\n    - {frame: world, position_m: [0, 0, 20]}\n")
    (_, el0, _), (_, el1, w1) = _detected_angles(sc)
    assert math.degrees(el0) == pytest.approx(0.0, abs=0.02)
    assert math.degrees(el1) == pytest.approx(0.3, abs=0.02)
    np.testing.assert_allclose(w1, [0, 0, 20], atol=0.03)


@pytest.mark.parametrize("stop_and_hop", [True, False])
def test_a_platform_turning_while_the_echo_flies(stop_and_hop):
    """Rolling at 10°/s through upright at ping 1, the sonar has turned a further ω·2r/c = 0.26°
    by the time the echo of a target 20 m below arrives: the receive leg's pose is the one the
    image's azimuth reports, unless stop-and-hop keeps the transmit pose (then exactly the roll
    at transmission, 0°)."""
    sc = scene("pings: {count: 2}\nsonar: {motion: {kind: series, series: {time_s: [0, 1, 2], "
               "roll_deg: [-10, 0, 10]}}}\neffects: {stop_and_hop: %s}\n"
               "targets:\n  points:\n    - {frame: world, position_m: [0, 0, 20]}\n"
               % str(stop_and_hop).lower())
    (_, _, _), (az1, _, w1) = _detected_angles(sc)
    lag = 0.0 if stop_and_hop else 10.0 * 2 * 20.0 / 1530.0
    assert math.degrees(az1) == pytest.approx(lag, abs=0.05)


def test_a_swell_and_a_csv_series_give_the_poses_they_describe(tmp_path):
    from acoustics.scene import load_scene
    from acoustics.simulation.setup import make_setup
    csv = tmp_path / "motion.csv"
    csv.write_text("time_s,roll_deg,pitch_deg,heave_m\n0,0,0,0\n2,4,-2,0.5\n")
    p = tmp_path / "s.yaml"
    p.write_text(QUIET + "sonar: {motion: {kind: file, file: motion.csv}}\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        setup = make_setup(load_scene(p))
    roll, pitch, yaw, heave = setup.platform.attitude(1.0)   # halfway: linear interpolation
    assert math.degrees(roll) == pytest.approx(2.0) and math.degrees(pitch) == pytest.approx(-1.0)
    assert heave == pytest.approx(0.25)
    pose = setup.pose_at(1)
    assert pose.position_m[2] == pytest.approx(-0.25)        # heave lifts: z is depth
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,roll_deg\n0,zero\n")
    p.write_text(QUIET + "sonar: {motion: {kind: file, file: bad.csv}}\n")
    from acoustics.sonar.platform import MotionFileError
    with pytest.raises(MotionFileError, match=r"bad.csv:2: column roll_deg"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SceneWarning)
            make_setup(load_scene(p))


# ------------------------------------------------------------------ within-ping motion
def _detected_range(doppler: bool, speed: float):
    sc = scene(f"effects: {{doppler: {str(doppler).lower()}, doppler_bin_hz: 2.0}}\n"
               f"targets:\n  points:\n    - {{frame: world, position_m: [0, 0, 20], "
               f"velocity_m_s: [0, 0, {-speed}]}}\n")
    tree = processing.count(acoustics.simulate(sc, pings=[0]),
                            {"detect": {"method": "fraction_of_peak", "fraction": 0.5}})
    det = processing.detections_of(tree)
    i = int(np.argmax(det["amplitude"].values))
    return float(det["range_m"].values[i]), sc


def test_doppler_of_a_closing_target_shifts_its_range_as_the_lfm_coupling_predicts():
    """An up-chirp shifted by f_d is the chirp f_d/μ earlier (μ = B/T): a target closing at v
    reads Δr = −(c/2)(2 v f0/c)(T/B) nearer — 15 cm at 1 m/s — and with the effect off, where it is."""
    r_off, sc = _detected_range(False, 1.0)
    r_on, _ = _detected_range(True, 1.0)
    c, f0 = sc.medium.sound_speed_m_s, sc.signal.center_frequency_hz
    shift = -(c / 2) * (2 * 1.0 * f0 / c) * sc.signal.duration_s / sc.signal.bandwidth_hz
    assert r_off == pytest.approx(20.0, abs=0.005)
    assert r_on - r_off == pytest.approx(shift, abs=0.01)


# ------------------------------------------------------------------ meshes seen from a moving sonar
MOVING_MESHES = """pings: {count: 3}
sonar: {pose: {position_m: [0, 0, 1.0]},
        motion: {kind: series, series: {time_s: [0, 2], roll_deg: [0, 4], pitch_deg: [0, -1.5],
                 yaw_deg: [0, 10], heave_m: [0, 0.6]}}}
targets:
  points:
    - {frame: world, position_m: [0.3, 0.5, 21.0]}
    - {frame: world, position_m: [-0.4, 1.2, 19.0]}
  meshes:
    - {name: ball, frame: world, mesh: {shape: sphere, center_m: [0.2, -0.3, 18.0], radius_m: 0.15}}
boundaries:
  - {name: floor, role: floor, mesh: {shape: plane, center_m: [0, 0, 24.0], normal: [0, 0.05, -1.0],
     size_m: [30.0, 30.0]}, reflection: {model: rayleigh, density_kg_m3: 1900, sound_speed_m_s: 1700},
     scattering: {law: lambert, mu_db: -27}}
  - {name: rock, role: obstacle, mesh: {shape: box, center_m: [0.0, 1.0, 16.0], size_m: [0.8, 0.8, 0.8]}}
effects: {max_bounces: 1, reverberation: {enabled: true, rays_per_square_degree: 50}}
"""


def test_meshes_built_once_answer_as_a_scene_rebuilt_at_each_pose():
    """The ray scene is built once at rest and queried through each ping's view; a scene built
    anew in that ping's sonar frame (the independent way) must give the same shadows, multipath
    image points and coefficients, mesh-target facets and reverberation hits."""
    from acoustics.paths.meshes import scene_meshes
    from acoustics.paths.ray_scene import build_ray_scene
    from acoustics.simulation.setup import RunCache, make_setup
    from acoustics.targets.draw import draw_targets
    sc = scene(MOVING_MESHES)
    setup = make_setup(sc)
    cache = RunCache(setup)
    for ping in (1, 2):
        pose = setup.pose_at(ping)
        rs, view = cache.ray_scene_at(pose)
        assert rs is cache.ray_scene and view is not None          # nothing rebuilt
        fresh = build_ray_scene(scene_meshes(setup.rays.sources, pose), setup.sonar, setup.medium,
                                frequency_hz=setup.center_frequency_hz,
                                specular=setup.rays.specular, threads=setup.rays.threads)
        t = draw_targets(setup.targets, ping, pose)
        q = np.ones(len(t), complex)
        np.testing.assert_array_equal(rs.shadowed(t.position_sonar_m, view),
                                      fresh.shadowed(t.position_sonar_m))
        a = rs.multipath(t.position_sonar_m, q, 1, view)
        b = fresh.multipath(t.position_sonar_m, q, 1)
        assert len(a) == len(b) > 0
        np.testing.assert_allclose(a.p_tx, b.p_tx, atol=1e-9)
        np.testing.assert_allclose(a.p_rx, b.p_rx, atol=1e-9)
        np.testing.assert_allclose(a.strength, b.strength, atol=1e-12)
        a, b = rs.mesh_targets(view), fresh.mesh_targets()
        assert len(a) > 0 and len(a) == len(b)
        np.testing.assert_allclose(a.p_tx, b.p_tx, atol=1e-9)
        np.testing.assert_allclose(a.strength, b.strength, rtol=1e-9)
        a = rs.reverberation(setup, ping, sc.seed, view)
        b = fresh.reverberation(setup, ping, sc.seed)
        # the same rays (directions fixed in the sonar frame) meet the same floor: their hit
        # points agree to Embree's float32 rounding, refined in float64
        assert len(a) > 100 and len(a) == len(b)
        np.testing.assert_allclose(a.p_tx, b.p_tx, atol=1e-6)
        np.testing.assert_allclose(np.abs(a.strength), np.abs(b.strength), rtol=1e-6)


def test_a_moving_sonar_reverberates_from_where_it_is():
    """Heave of +0.6 m (up) lifts the sonar away from the floor (roll and pitch aside): the
    nearest reverberation hit of a flat floor seen straight down moves out by the heave."""
    sc = scene(MOVING_MESHES.replace("roll_deg: [0, 4], pitch_deg: [0, -1.5],\n                 yaw_deg: [0, 10], ", "")
               .replace("normal: [0, 0.05, -1.0]", "normal: [0, 0, -1.0]"))
    from acoustics.simulation.setup import RunCache, make_setup
    setup = make_setup(sc)
    cache = RunCache(setup)
    near = []
    for ping in (0, 2):
        rs, view = cache.ray_scene_at(setup.pose_at(ping))
        vs = rs.reverberation(setup, ping, sc.seed, view)
        near.append(np.linalg.norm(vs.p_tx, axis=1).min())
    assert near[1] - near[0] == pytest.approx(0.6, abs=0.01)


def test_a_sonar_frame_mesh_rides_with_the_moving_sonar():
    """A sphere given in the sonar frame (hung from the sonar) stays put in the sonar frame
    while the world-frame floor moves: the scene is rebuilt per pose for this mix, and the
    sphere's facets come back at the same sonar-frame places every ping."""
    from acoustics.simulation.setup import RunCache, make_setup
    sc = scene(MOVING_MESHES.replace("{name: ball, frame: world", "{name: ball, frame: sonar"))
    setup = make_setup(sc)
    cache = RunCache(setup)
    got = []
    for ping in (0, 2):
        rs, view = cache.ray_scene_at(setup.pose_at(ping))
        assert view is None and rs is not cache.ray_scene
        got.append(rs.mesh_targets())
    np.testing.assert_allclose(got[0].p_tx, got[1].p_tx, atol=1e-12)


def test_motion_that_leaves_the_water_is_refused():
    """A heave that lifts the sonar out of the water, or a straight path that leaves it by the
    last ping, is a scene error naming the key (not a simulation of a sonar in the air)."""
    with pytest.raises(acoustics.SceneError, match=r"sonar\.motion: .*above the sea surface"):
        scene("pings: {count: 10}\nsonar: {pose: {position_m: [0, 0, 0.5]}, motion: {kind: swell, "
              "swell: {heave_amplitude_m: 1.0}}}\n")
    with pytest.raises(acoustics.SceneError, match=r"targets\.points\[0\]\.velocity_m_s: .*last ping"):
        scene("pings: {count: 10}\ntargets:\n  points:\n"
              "    - {frame: world, position_m: [0, 0, 2], velocity_m_s: [0, 0, -0.5]}\n")
