"""Per-arrival ground truth (/Vendor_specific/Arrivals): the table lists every path a ping's
echoes are made of, with delays and levels that image-source geometry predicts independently,
and summing its rows through the array and the pulse gives back the simulated samples."""
from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

import acoustics
from acoustics.scene.load import scene_from_text
from acoustics.simulation.setup import RunCache, make_setup
from acoustics.synthesis.synthesize import synthesize
from processing.base.contract import ARRIVALS_GROUP

#: a target 2 m under a flat sea (R = −1) over a flat floor at 12 m (R = 0.5), seen by a
#: horizontal sonar 5 m down: the waveguide of issue 30's first must-show
WAVEGUIDE = """
schema_version: 1
name: waveguide
seed: 3
sonar:
  pose: {position_m: [0.0, 0.0, 5.0], boresight: [1.0, 0.0, 0.0], receiver_axis: [0.0, 1.0, 0.0]}
medium: {sound_speed_m_s: 1500.0}
targets:
  points:
    - {frame: world, position_m: [20.0, 0.0, 2.0], label: fish}
boundaries:
  - name: sea surface
    role: surface
    mesh: {shape: plane, center_m: [20.0, 0.0, 0.0], normal: [0.0, 0.0, 1.0], size_m: [200.0, 200.0]}
  - name: sea floor
    role: floor
    mesh: {shape: plane, center_m: [20.0, 0.0, 12.0], normal: [0.0, 0.0, -1.0], size_m: [200.0, 200.0]}
    reflection: {model: constant, coefficient: 0.5}
    scattering: null
effects: {max_bounces: 2, arrivals: {enabled: true, floor_db: null}}
"""


def _scene(text=WAVEGUIDE):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return scene_from_text(text)


def _table(tree):
    return tree[ARRIVALS_GROUP].to_dataset()


@pytest.fixture(scope="module")
def waveguide():
    scene = _scene()
    return scene, acoustics.simulate(scene, pings=1)


def _expected_paths(scene, setup):
    """Every path up to two bounces per leg by image sources, computed here from the geometry
    alone: {sequence: (delay s, level dB)}."""
    pose = setup.sonar.pose
    t_w = pose.to_world(setup.model.transmitter.phase_center_m)
    r_w = pose.to_world(setup.model.receiver.phase_center_m)
    target = np.array([20.0, 0.0, 2.0])
    depth = {"S": 0.0, "F": 12.0}
    coef = {"S": -1.0, "F": 0.5}

    def image(p, seq):        # p seen through the bounces of seq, nearest the observer first
        for b in reversed(seq):
            p = p * [1, 1, -1] + [0, 0, 2 * depth[b]]
        return p

    seqs = [()] + [s for k in (1, 2) for s in itertools.product("SF", repeat=k) if len(set(s)) == k]
    alpha = scene.medium.absorption_db_per_m
    c = scene.medium.sound_speed_m_s
    out = {}
    for tx, rx in itertools.product(seqs, seqs):
        l1 = np.linalg.norm(image(target, tx) - t_w)          # transmit leg, unfolded
        l2 = np.linalg.norm(image(target, rx) - r_w)          # receive leg from the receiver
        name = "-".join(list(tx) + ["T"] + list(reversed(rx)))
        gain = np.prod([coef[b] for b in tx + rx])
        out[name] = ((l1 + l2) / c, 20 * np.log10(abs(gain) / (l1 * l2)) - alpha * (l1 + l2))
    return out


def test_waveguide_paths_match_image_sources(waveguide):
    scene, tree = waveguide
    tab = _table(tree)
    want = _expected_paths(scene, make_setup(scene))
    got = dict(zip(tab["arrival_sequence"].values.astype(str), zip(tab["arrival_delay"].values,
                                                                  tab["arrival_level"].values)))
    assert len(want) == 25 and sorted(got) == sorted(want)          # direct + 24 bounced, each once
    ts = 20 * np.log10(float(tree["Vendor_specific"].ds["target_backscatter_amplitude"][0]))
    for seq, (tau, lvl) in want.items():
        assert abs(got[seq][0] - tau) < 1e-9, seq                  # 1 ns
        assert abs(got[seq][1] - (lvl + ts)) < 0.1, seq            # 0.1 dB
    # every path is the target's; the bounces counted; nothing shadowed
    assert set(tab["arrival_target_id"].values) == {0}
    n_b = np.array([s.count("S") + s.count("F") for s in tab["arrival_sequence"].values.astype(str)])
    assert np.array_equal(tab["arrival_bounces"].values, n_b)
    assert not tab["arrival_shadowed"].values.any()


def test_directions_point_at_the_images(waveguide):
    """A path that leaves via the surface leaves upwards (−y_s: the fan's +y points down)."""
    _, tree = waveguide
    tab = _table(tree)
    seq = tab["arrival_sequence"].values.astype(str)
    el_dep = tab["arrival_departure_elevation"].values
    el_arr = tab["arrival_elevation"].values
    assert np.all(el_dep[np.char.startswith(seq, "S-")] < 0)
    assert np.all(el_dep[np.char.startswith(seq, "F-")] > 0)
    assert np.all(el_arr[np.char.endswith(seq, "-S")] < 0)
    assert np.all(el_arr[np.char.endswith(seq, "-F")] > 0)


def test_level_floor_keeps_the_strong_paths():
    scene = _scene(WAVEGUIDE.replace("floor_db: null", "floor_db: -12.0"))
    tab = _table(acoustics.simulate(scene, pings=1))
    lvl = tab["arrival_level"].values
    assert lvl.max() - lvl.min() <= 12.0 and "T" in tab["arrival_sequence"].values.astype(str)
    assert tab.sizes["arrival"] < 25


def test_off_by_default_costs_nothing():
    scene = _scene(WAVEGUIDE.replace("arrivals: {enabled: true, floor_db: null}", "doppler: false"))
    tree = acoustics.simulate(scene, pings=1)
    assert "arrivals" not in tree["Provenance"].ds.attrs["stages_run"].split(",")
    assert "Arrivals" not in tree["Vendor_specific"].children


def test_old_key_still_read():
    with pytest.warns(FutureWarning, match="max_bounces"):
        scene = scene_from_text(WAVEGUIDE.replace("max_bounces: 2", "multipath_order: 2"))
    assert scene.effects.max_bounces == 2


def _resynthesise(scene, tree):
    """The element samples of ping 0 rebuilt from the arrivals table alone: each row a scatterer
    at its unfolded legs' ends, of the strength its amplitude implies, through the array and the
    pulse."""
    setup = make_setup(scene)
    tab = _table(tree)
    model, medium = setup.model, setup.medium

    def point(origin, r, az, el):
        u = np.stack([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)], -1)
        return origin + r[:, None] * u

    r1, r2 = tab["arrival_transmit_range"].values, tab["arrival_receive_range"].values
    p_tx = point(model.transmitter.phase_center_m, r1, tab["arrival_departure_azimuth"].values,
                 tab["arrival_departure_elevation"].values)
    p_rx = point(model.receiver.phase_center_m, r2, tab["arrival_azimuth"].values,
                 tab["arrival_elevation"].values)
    amp = tab["arrival_amplitude_r"].values + 1j * tab["arrival_amplitude_i"].values
    g = medium.one_way_gain(r1) * medium.one_way_gain(r2)
    q = amp / (g * np.exp(-1j * model.wavenumber_rad_m * (r1 + r2)))
    s, fx = scene.sampling, scene.effects
    return synthesize(model, p_tx, q, pulse=setup.pulse, rate_hz=s.rate_hz, n_samples=s.samples,
                      t0_s=s.time_offset_s, method=fx.synthesis, kernel_length=fx.kernel_length,
                      oversampling=fx.oversampling, receive_positions_m=p_rx,
                      doppler_hz=tab["arrival_doppler"].values if fx.doppler else None)


def _samples(tree):
    g = tree["Sonar/Beam_group1"].ds
    return (g["backscatter_r"].values[0, 0] + 1j * g["backscatter_i"].values[0, 0]).T


@pytest.mark.parametrize("extra", ["", "reverberation"])
def test_arrivals_sum_to_the_samples(waveguide, extra):
    """Nothing is missing: the rows, summed through the array and the pulse, give the samples
    to the float32 precision the file stores them in (the fast synthesis' own error is the same
    in both: the same kernel evaluates the same paths)."""
    scene, tree = waveguide
    if extra:
        scene = _scene(REVERBERANT)
        tree = acoustics.simulate(scene, pings=1)
        seq = _table(tree)["arrival_sequence"].values.astype(str)
        assert (seq == "RF").sum() > 100 and (seq == "T").sum() == 1
        facet = _table(tree)["arrival_facet"].values[seq == "RF"]
        assert np.all(facet >= 0)
        assert set(_table(tree)["arrival_boundary"].values[seq == "RF"].astype(str)) == {"sea floor"}
    x = _samples(tree)
    y = _resynthesise(scene, tree)
    scale = np.max(np.abs(x))
    assert scale > 0
    assert np.max(np.abs(y - x)) < 1e-6 * scale


#: a sonar looking down at a target 10 m down over a flat, reverberant floor at 20 m
REVERBERANT = """
schema_version: 1
name: reverberant
seed: 4
medium: {sound_speed_m_s: 1500.0}
targets:
  points:
    - {range_m: 10.0, azimuth_deg: 5.0, elevation_deg: 0.0}
boundaries:
  - name: sea floor
    role: floor
    mesh: {shape: plane, center_m: [0.0, 0.0, 20.0], normal: [0.0, 0.0, -1.0], size_m: [60.0, 60.0]}
    reflection: {model: constant, coefficient: 0.5}
    scattering: {law: lambert, mu_db: -20.0}
effects: {max_bounces: 1, reverberation: {enabled: true, rays_per_square_degree: 4.0},
          arrivals: {enabled: true, floor_db: null}}
"""


SWELL = """
schema_version: 1
name: swell-waveguide
seed: 5
sonar:
  pose: {position_m: [0.0, 0.0, 4.0], boresight: [1.0, 0.0, 0.0], receiver_axis: [0.0, 1.0, 0.0]}
medium: {sound_speed_m_s: 1500.0}
targets:
  points:
    - {frame: world, position_m: [20.0, 0.0, 2.0]}
boundaries:
  - name: sea surface
    role: surface
    mesh:
      shape: swell
      center_m: [15.0, 0.0]
      size_m: [40.0, 16.0]
      resolution_m: 0.5
      waves: [{amplitude_m: 0.3, wavelength_m: 25.0, direction_deg: 0.0}]
  - name: sea floor
    role: floor
    mesh: {shape: plane, center_m: [20.0, 0.0, 12.0], normal: [0.0, 0.0, -1.0], size_m: [200.0, 200.0]}
    reflection: {model: constant, coefficient: 0.5}
    scattering: null
effects: {max_bounces: 2, arrivals: {enabled: true, floor_db: null}}
"""


def test_swell_bounces_are_listed():
    """Under a swell the curved surface's bounces appear (with their facets), alone and between
    floor bounces, each delay between those of flat surfaces at the crest and trough heights."""
    scene = _scene(SWELL)
    tree = acoustics.simulate(scene, pings=1)
    tab = _table(tree)
    seq = tab["arrival_sequence"].values.astype(str)
    for s in ("T", "S-T", "T-S", "S-T-S", "F-T", "S-F-T", "F-S-T", "S-T-F"):
        assert s in seq, s
    via = tab["arrival_via"].values.astype(str)
    assert all("sea surface#" in v for v, s in zip(via, seq) if "S" in s)
    setup = make_setup(scene)
    pose = setup.sonar.pose
    t_w = pose.to_world(setup.model.transmitter.phase_center_m)
    r_w = pose.to_world(setup.model.receiver.phase_center_m)
    target = np.array([20.0, 0.0, 2.0])
    c = scene.medium.sound_speed_m_s
    for s, tau in zip(seq, tab["arrival_delay"].values):
        legs = s.split("T")
        bounds = []
        for h in (-0.3, 0.3):   # the surface at the crest and trough heights (z is depth)
            def image(p, seq):
                for b in reversed(seq):
                    d = h if b == "S" else 12.0
                    p = p * [1, 1, -1] + [0, 0, 2 * d]
                return p
            tx = tuple(b for b in legs[0].split("-") if b)
            rx = tuple(reversed([b for b in legs[1].split("-") if b]))
            bounds.append((np.linalg.norm(image(target, tx) - t_w)
                           + np.linalg.norm(image(target, rx) - r_w)) / c)
        assert min(bounds) - 1e-9 <= tau <= max(bounds) + 1e-9, s
    # every row is a distinct path
    key = list(zip(seq, np.round(tab["arrival_delay"].values * 1e12)))
    assert len(set(key)) == len(key)


def test_written_group_follows_the_contract(waveguide, tmp_path, capsys):
    """The group goes through the contract's builder and survives a netCDF round trip; the CLI
    flag asks for it."""
    from abacus.cli.app import main
    from processing.base.dataset import open_tree
    from processing.base.groups import check_tree
    from processing.base.contract import GROUPS, node_path
    _, tree = waveguide
    assert check_tree(tree) == []
    assert {node_path(n.path) for n in tree.subtree} == set(GROUPS)
    out = tmp_path / "w.nc"
    scene_file = tmp_path / "w.yaml"
    scene_file.write_text(WAVEGUIDE.replace("arrivals: {enabled: true, floor_db: null}", "doppler: false"))
    assert main(["simulate", str(scene_file), "-o", str(out), "--pings", "1", "--arrivals"]) == 0
    back = open_tree(out)["Vendor_specific/Arrivals"].to_dataset()
    mine = _table(tree)
    # the scene's default floor (−80 dB) keeps every one of these 25 paths (within 40 dB)
    assert back.sizes["arrival"] == 25
    assert np.array_equal(back["arrival_sequence"].values.astype(str),
                          mine["arrival_sequence"].values.astype(str))
    assert np.allclose(back["arrival_delay"].values, mine["arrival_delay"].values, rtol=0, atol=1e-15)
    assert "25 arrival(s)" in capsys.readouterr().out


def test_doppler_of_each_path_and_resynthesis_with_doppler():
    """A target closing at 1 m/s along world x: each path's Doppler is −f0/c times the rate its
    unfolded length changes (the image moves with the target, mirrored: along x unchanged), and
    the rows still sum to the samples with the shifts applied."""
    text = (WAVEGUIDE.replace("label: fish}", "label: fish, velocity_m_s: [-1.0, 0.0, 0.0]}")
            .replace("effects: {", "effects: {doppler: true, "))
    scene = _scene(text)
    tree = acoustics.simulate(scene, pings=1)
    tab = _table(tree)
    setup = make_setup(scene)
    pose = setup.sonar.pose
    t_w = pose.to_world(setup.model.transmitter.phase_center_m)
    r_w = pose.to_world(setup.model.receiver.phase_center_m)
    target, v = np.array([20.0, 0.0, 2.0]), np.array([-1.0, 0.0, 0.0])
    f0, c = scene.signal.center_frequency_hz, scene.medium.sound_speed_m_s

    def image(p, seq):
        for b in reversed(seq):
            p = p * [1, 1, -1] + [0, 0, 2 * (0.0 if b == "S" else 12.0)]
        return p

    for s, fd in zip(tab["arrival_sequence"].values.astype(str), tab["arrival_doppler"].values):
        tx = tuple(b for b in s.split("T")[0].split("-") if b)
        rx = tuple(reversed([b for b in s.split("T")[1].split("-") if b]))
        rate = 0.0
        for seq, origin in ((tx, t_w), (rx, r_w)):
            d = image(target, seq) - origin
            rate += d @ v / np.linalg.norm(d)           # horizontal velocity: mirrors unchanged
        assert abs(fd - (-f0 * rate / c)) < 1e-6 * f0 / c, s
    x = _samples(tree)
    assert np.max(np.abs(_resynthesise(scene, tree) - x)) < 1e-6 * np.max(np.abs(x))


def test_old_and_new_key_together_is_one_clear_line():
    from acoustics.scene.errors import SceneError
    with pytest.raises(SceneError, match="multipath_order and max_bounces both given"):
        scene_from_text(WAVEGUIDE.replace("max_bounces: 2", "max_bounces: 2, multipath_order: 2"))


def test_a_path_reached_twice_counts_once():
    """Two legs of one sequence that reach the same image point (a glint found from two facets)
    make one path, not two; distinct glints stay."""
    scene = _scene(SWELL)
    rs = RunCache(make_setup(scene)).ray_scene
    t_tgt = np.array([0, 0, 0])
    t_seq = np.array([1, 1, 1])
    t_pt = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 10.0 + 2e-5], [0.0, 0.5, 10.0]])
    r_tgt, r_seq, r_pt = np.array([0]), np.array([0]), np.array([[0.0, 0.0, 9.0]])
    ti, ri = rs.distinct_paths(np.arange(3), np.zeros(3, int), t_tgt, t_seq, r_seq, t_pt, r_pt)
    assert sorted(ti.tolist()) in ([0, 2], [1, 2]) and ri.tolist() == [0, 0]
    assert rs.caster.rays_cast.get("duplicate_paths_dropped") == 1


def test_swell_bounce_delays_are_fermat_paths():
    """Under the swell, the S-T, T-S and S-T-S delays are the stationary (Fermat) path lengths
    over the sea's own height field, found here by a plain minimisation, to 1 ns."""
    from scipy.optimize import minimize
    scene = _scene(SWELL.replace("max_bounces: 2", "max_bounces: 1"))
    tree = acoustics.simulate(scene, pings=1)
    tab = _table(tree)
    setup = make_setup(scene)
    sea = next(sm for sm in setup.rays.meshes if sm.moving)
    rot, shift = sea.placement[:3, :3], sea.placement[:3, 3]
    t_s = setup.model.transmitter.phase_center_m
    r_s = setup.model.receiver.phase_center_m
    truth = tree["Vendor_specific"].ds
    p_s = np.array([float(truth[f"target_{a}"][0]) for a in "xyz"])
    c = scene.medium.sound_speed_m_s

    def fermat(origin):
        def length(xy):
            z = sea.surface.height(np.array([xy[0]]), np.array([xy[1]]), sea.time_s)[0][0]
            x = rot @ np.array([xy[0], xy[1], z]) + shift
            return np.linalg.norm(x - origin) + np.linalg.norm(x - p_s)
        start = np.array([10.0, 0.0])            # near the flat-sea bounce point, world x
        res = minimize(length, start, method="Nelder-Mead",
                       options={"xatol": 1e-9, "fatol": 1e-12, "maxiter": 4000})
        return res.fun

    l_tx, l_rx = fermat(t_s), fermat(r_s)
    want = {"S-T": l_tx + np.linalg.norm(p_s - r_s), "T-S": np.linalg.norm(p_s - t_s) + l_rx,
            "S-T-S": l_tx + l_rx}
    seq = tab["arrival_sequence"].values.astype(str)
    for s, length in want.items():
        got = tab["arrival_delay"].values[seq == s]
        assert got.size == 1, s
        assert abs(got[0] - length / c) < 1e-9, s


def test_old_key_out_of_range_is_one_line():
    from acoustics.scene.errors import SceneError
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # no deprecation warning before the error
        with pytest.raises(SceneError, match=r"multipath_order \(now max_bounces\) must be an integer from 0 to 4"):
            scene_from_text(WAVEGUIDE.replace("max_bounces: 2", "multipath_order: 9"))
