"""Single targets and their TS (processing/backscatter/single_targets.py), and the exports a user takes to
other tools: the single-target CSV and `abacus sv`."""
from __future__ import annotations

import csv
import json
import warnings

import numpy as np
import pytest

import acoustics
import processing
from processing.backscatter.target_table import single_target_table

from .conftest import ROOT
from .test_cli import abacus


def _sphere_ts(az_deg, el_deg):
    th, ph = np.radians(az_deg), np.radians(el_deg)
    c = 20.0 * np.array([np.cos(ph) * np.sin(th), np.sin(ph), np.cos(ph) * np.cos(th)])
    scene = acoustics.load_scene(ROOT / "scenes" / "calibration_sphere.yaml").with_updates(
        {"targets.meshes[0].mesh.center_m": c.tolist()})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = processing.detect(acoustics.simulate(scene))
    t = single_target_table(tree)
    i = int(np.nanargmax(t["amplitude"].values))
    return float(t["ts_comp_db"].values[i]), float(t["ts_uncomp_db"].values[i]), float(t["beam_pattern_db"].values[i])


def test_ts_comp_of_a_sphere_off_axis_is_its_on_axis_value():
    """The rigid calibration sphere (a = 19.05 mm, physical-optics echo off its mesh) moved off
    axis to where the two-way pattern is −1.7 to −5.5 dB: its beam-compensated TS is its on-axis
    TS within 0.5 dB (measured: within 0.03 dB), while the uncompensated TS falls with the pattern."""
    on, on_u, _ = _sphere_ts(0.0, 0.0)
    assert on == pytest.approx(-40.4, abs=0.5)          # 10 log10(a²/4), docs/validation.md
    for az, el in ((4.0, 0.0), (-5.5, 0.15), (2.0, -0.25)):
        comp, uncomp, pattern = _sphere_ts(az, el)
        assert pattern < -1.0, "not off axis enough to test the compensation"
        assert comp == pytest.approx(on, abs=0.5)
        assert uncomp == pytest.approx(on + pattern, abs=0.5)


def test_count_writes_single_targets_and_sv_writes_mvbs_and_nasc(tmp_path):
    r = abacus("simulate", "fish_passing", "-o", "fp.nc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = abacus("count", "fp.nc", "--targets-csv", "st.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(tmp_path / "st.csv")))
    assert rows and {"Ping_index", "Target_range", "TS_comp", "TS_uncomp", "Angle_azimuth_deg",
                     "Angle_elevation_deg", "Target_world_z_m"} <= set(rows[0])
    # the fish (TS −41…−35 dB, docs/scenes.md) is among the single targets with a finite TS_comp
    ts = np.array([float(x["TS_comp"]) for x in rows if x["TS_comp"]])
    assert ts.size and np.any(np.abs(ts + 38.0) < 4.0) and np.all(ts >= -70.0)
    r = abacus("sv", "fp.nc", "--json", "--layer", "15:20", "--csv", "mvbs.csv", "--nasc-csv", "nasc.csv",
               "--range-bin", "1", "--ping-bin", "7", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["grid"]["ping_bins"] == 3 and out["layers"][0]["range_m"] == [15.0, 20.0]
    assert out["layers"][0]["NASC_mean_m2_nmi2"] > 0
    mv = list(csv.DictReader(open(tmp_path / "mvbs.csv")))
    assert len(mv) == 3 * out["grid"]["range_bins"] * out["grid"]["beams"]
    assert len(list(csv.DictReader(open(tmp_path / "nasc.csv")))) == 21 * out["grid"]["beams"]
    r = abacus("sv", "fp.nc", "--layer", "20:15", cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "--layer" in r.stderr


# ------------------------------------------------ single-target detection by the echosounder criteria
from processing.backscatter.echo_criteria import RULES, echo_shape, verdicts  # noqa: E402
from processing.backscatter.target_strength import BeamPattern  # noqa: E402
from processing.pipeline import RecordChain  # noqa: E402
from processing.settings import SingleTargetSettings  # noqa: E402


def test_echo_length_and_phase_deviation_of_a_known_envelope():
    """A Gaussian envelope exp(−t²/2σ²) is 6 dB down at ±σ√(2 ln 10^(6/20)): the measured length
    is that within a hundredth of a sample; a linear phase ramp of slope s (rad per sample)
    over the n samples within the ends has the standard deviation s·√((n²−1)/12)."""
    step, sigma = 0.004, 0.02
    r = np.arange(400) * step
    env = np.exp(-0.5 * ((r - 0.8) / sigma) ** 2)
    width = 2 * sigma * np.sqrt(2 * np.log(10 ** (6 / 20)))
    slope = 0.01
    cross = env ** 2 * np.exp(1j * slope * np.arange(r.size))
    rslope = 0.02
    profiles = np.stack([env * np.exp(1j * rslope * np.arange(r.size)), env.astype(complex)], -1)
    shape = echo_shape(env, 200, range_step_m=step, cross=cross, profiles=profiles,
                       neighbours=np.stack([0.5 * env, 0.5 * env], -1))
    length, pd, off = shape[:3]
    # the ends are interpolated linearly on a curved flank: second order in the step
    assert length == pytest.approx(width, abs=0.01 * step + step**2 / sigma)
    lo, hi = 0.8 - width / 2, 0.8 + width / 2
    n = int(np.floor(hi / step + 1e-9)) - int(np.ceil(lo / step - 1e-9)) + 1
    assert pd == pytest.approx(np.degrees(slope * np.sqrt((n * n - 1) / 12)), rel=1e-6)
    assert off == pytest.approx(0.0, abs=1e-12)         # symmetric neighbours: the peak stays put
    # the range phase: the mean over the images of a ramp's deviation and a flat phase's zero
    assert shape.range_phase_deviation_deg == pytest.approx(
        0.5 * np.degrees(rslope * np.sqrt((n * n - 1) / 12)), rel=1e-6)
    assert np.isnan(shape.noise_phase_deg)              # no noise level given: no noise share
    # an echo that runs off the image has no length (rule image_edge), never a truncated one
    assert np.isnan(echo_shape(env[:205], 200, range_step_m=step)[0])


def test_two_echoes_within_the_range_resolution_turn_the_range_phase_at_first_order():
    """Two echoes of a Gaussian point response p (σ_p), equal amplitudes, δ = 0.05 of the −6 dB
    width apart, relative phase φ: to first order in δ the sum's phase along range is
    Im(e^{iφ}/(1 + e^{iφ})) δ r / σ_p² (p′/p = −r/σ_p²), so its standard deviation over the
    echo's samples is that slope times the samples' spread in r, within (δ/σ_p)² ≈ 1.4 %; in
    phase (φ = 0) the sum is one echo at the centroid and its phase is flat."""
    step, sp = 0.002, 0.02
    r = np.arange(600) * step - 0.6
    width = 2 * sp * np.sqrt(2 * np.log(10 ** (6 / 20)))
    delta = 0.05 * width
    for phi in (np.pi / 2, 2.0, -1.0):
        echo = np.exp(-0.5 * (r / sp) ** 2) + np.exp(1j * phi) * np.exp(-0.5 * ((r - delta) / sp) ** 2)
        env = np.abs(echo)
        sh = echo_shape(env, int(np.argmax(env)), range_step_m=step, profiles=echo[:, None])
        inside = r[env >= 0.5 * env.max()]
        beta = np.exp(1j * phi) / (1 + np.exp(1j * phi))
        predicted = np.degrees(abs(beta.imag) * delta / sp ** 2 * np.std(inside))
        assert sh.range_phase_deviation_deg == pytest.approx(predicted, rel=0.05)
    inphase = np.exp(-0.5 * (r / sp) ** 2) + np.exp(-0.5 * ((r - delta) / sp) ** 2)
    sh = echo_shape(np.abs(inphase), int(np.argmax(np.abs(inphase))), range_step_m=step,
                    profiles=inphase.astype(complex)[:, None])
    assert sh.range_phase_deviation_deg == pytest.approx(0.0, abs=1e-9)


def test_noise_alone_gives_the_phase_spread_of_sigma_over_the_magnitude():
    """One echo (a Gaussian envelope, flat phase) in two channels with independent white complex
    noise of Rayleigh scale σ: per sample the phase noise is σ/|I| (small-noise limit), so the
    mean square of the echo's range phase deviation is (1 − 1/n) mean(σ²/|I|²) (the samples'
    mean is removed), and that of ψ_AB's the same with both channels' noise. Monte Carlo at 40
    dB peak SNR, 2000 echoes: within 5 % (the estimate's spread is ≈ 2 %)."""
    rng = np.random.default_rng(3)
    step, width, sigma, m = 0.004, 0.02, 0.01, 2000
    r = np.arange(120) * step
    env = np.exp(-0.5 * ((r - 0.24) / width) ** 2)           # peak 1: 20 log10(1/σ) = 40 dB
    rp, ab, noise1, noise_ab, nrows = [], [], [], [], []
    for _ in range(m):
        a = env + sigma * (rng.standard_normal(r.size) + 1j * rng.standard_normal(r.size))
        b = env + sigma * (rng.standard_normal(r.size) + 1j * rng.standard_normal(r.size))
        sh = echo_shape(np.abs(a), 60, range_step_m=step, cross=a * np.conj(b), profiles=a[:, None],
                        noise_sigma=sigma)
        rp.append(sh.range_phase_deviation_deg)
        ab.append(sh.phase_deviation_deg)
        noise1.append(sh.noise_phase_deg)
        noise_ab.append(sh.noise_phase_ab_deg)
        nrows.append(int(round(sh.length_m / step)))
    shrink = 1 - 1 / np.mean(nrows)
    assert np.sqrt(np.mean(np.square(rp))) == pytest.approx(np.sqrt(shrink * np.mean(np.square(noise1))), rel=0.05)
    assert np.sqrt(np.mean(np.square(ab))) == pytest.approx(np.sqrt(shrink * np.mean(np.square(noise_ab))), rel=0.05)
    # ψ_AB carries both channels' noise: √2 one channel's (equal magnitudes)
    assert np.mean(noise_ab) / np.mean(noise1) == pytest.approx(np.sqrt(2), rel=0.01)


def test_split_phase_noise_gain_against_beamformed_noise():
    """The split-aperture phase of the beam-domain peak (a parabola through three FFT beams of an
    8-element Hamming-weighted array, 32 beams) moved by element noise alone: its standard
    deviation is g_split σ/|I| (σ the beams' Rayleigh scale, |I| the echo's beam magnitude),
    g_split from :func:`split_phase_noise_gain`. Monte Carlo, 20000 draws at 40 dB: within 5 %."""
    from processing.backscatter.echo_criteria import split_phase_noise_gain
    from processing.detection.peaks import refine
    rng = np.random.default_rng(5)
    lam, pitch, n, nbeam = 0.00364, 0.015, 8, 32
    x = (np.arange(n) - (n - 1) / 2) * pitch
    w = np.hamming(n)
    du = lam / (nbeam * pitch)
    u = np.array([-du, 0.0, du])                         # the echo on the centre beam
    steer = np.exp(-1j * 2 * np.pi / lam * np.outer(u, x)) * w   # (3 beams, n elements)
    s_el, m = 0.01, 20000
    noise = s_el * (rng.standard_normal((m, n)) + 1j * rng.standard_normal((m, n)))
    beams = np.abs((1.0 + noise) @ steer.T)             # a plane wave on axis, amplitude 1
    off, _ = refine(beams[:, 0], beams[:, 1], beams[:, 2])
    d_split = (x[-1] - x[0]) * n / (2 * (n - 1))
    split_deg = np.degrees(2 * np.pi / lam * d_split * du * off)
    sigma_beam = s_el * np.sqrt(np.sum(w ** 2))         # per quadrature, in the beam
    magnitude = np.sum(w)
    g = split_phase_noise_gain(x, w, du, lam, d_split)
    assert np.std(split_deg) == pytest.approx(g * np.degrees(sigma_beam / magnitude), rel=0.05)


def test_phase_limits_widen_with_the_noise_in_quadrature(tmp_path):
    """k = 0 is the fixed limit (EK60/Echoview); k > 0 adds k σ_noise in quadrature, per plane;
    the range phase rule follows the angle rules."""
    from processing.backscatter.echo_criteria import phase_limit_deg
    assert phase_limit_deg(3.0, [4.0 / 2, np.nan], 2.0) == pytest.approx([5.0, 3.0])
    assert np.all(np.isinf(phase_limit_deg(None, [1.0], 2.0)))
    n = 3
    ok = dict(sidelobe=np.zeros(n, bool), ts_comp_db=np.full(n, -40.0), echo_length=np.ones(n),
              compensation_db=np.zeros(n), spacing=np.full(n, np.inf))
    # planes: elevation 4.5° with noise 2° (limit 5°), azimuth 1° with noise 0 -> passes at k = 2
    dev = np.array([[4.5, 1.0, 0.5], [1.0, 5.5, 0.5]])
    nz = np.array([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    rp, rpn = np.array([0.5, 0.5, 1.2]), np.array([0.1, 0.1, 0.1])
    k2 = SingleTargetSettings(phase_deviation_sigmas=2.0)
    k0 = SingleTargetSettings(phase_deviation_sigmas=0.0)
    got = verdicts(**ok, phase_deviation_deg=dev, phase_noise_deg=nz, range_phase_deviation_deg=rp,
                   range_phase_noise_deg=rpn, settings=k2).tolist()
    assert got == ["", "maximum_phase_deviation", "maximum_range_phase_deviation"]
    got = verdicts(**ok, phase_deviation_deg=dev, phase_noise_deg=nz, range_phase_deviation_deg=rp,
                   range_phase_noise_deg=rpn, settings=k0).tolist()
    assert got == ["maximum_phase_deviation", "maximum_phase_deviation", "maximum_range_phase_deviation"]
    # a bad value is one line naming the key
    from processing.base.config import ConfigError
    from processing.settings import load_settings
    bad = tmp_path / "bad.yaml"
    bad.write_text("single_target: {phase_deviation_sigmas: -1}\n")
    with pytest.raises(ConfigError) as e:
        load_settings(bad)
    assert "phase_deviation_sigmas" in str(e.value) and len(str(e.value).strip().splitlines()) == 1
    off = SingleTargetSettings(maximum_range_phase_deviation_deg=None)
    assert verdicts(**ok, phase_deviation_deg=dev[:, 2:].repeat(3, 1), range_phase_deviation_deg=rp,
                    settings=off).tolist() == [""] * n


def test_a_candidate_is_named_by_the_first_rule_it_fails():
    st = SingleTargetSettings()
    n = 5
    ok = dict(sidelobe=np.zeros(n, bool), ts_comp_db=np.full(n, -40.0), echo_length=np.ones(n),
              phase_deviation_deg=np.zeros(n), compensation_db=np.zeros(n), spacing=np.full(n, np.inf))
    bad = {**ok, "ts_comp_db": np.array([-40, -60, -60, -40, np.nan]),
           "echo_length": np.array([1.0, 1.0, 1.5, 0.5, 1.0]),
           "phase_deviation_deg": np.array([0.0, 0.0, 0.0, 0.0, 0.0]),
           "spacing": np.array([0.5, np.inf, np.inf, np.inf, np.inf])}
    assert list(verdicts(**ok, settings=st)) == [""] * n
    assert list(verdicts(**bad, settings=st)) == ["minimum_echo_spacing", "TS_threshold", "TS_threshold",
                                                  "minimum_echo_duration", "gain_compensation"]
    assert set(RULES) >= {"TS_threshold", "gain_compensation", "maximum_phase_deviation"}
    # no phase (normal mode): the phase rule is skipped, not failed
    assert verdicts(**{**ok, "phase_deviation_deg": np.full(n, np.nan)}, settings=st).tolist() == [""] * n


def test_near_field_of_a_line_aperture_is_the_fresnel_integral():
    """A straight line of 81 small in-phase elements (L = 0.243 m) on its axis at r: the exact
    sum over element paths relative to the far-field sum is the Fresnel integral of a line
    aperture, |C(a) + jS(a)| / a with a = (L/2)√(2/(λ r)) (scipy.special.fresnel), within the
    discrete sum's departure from the continuous aperture (< 0.01 dB here)."""
    from scipy.special import fresnel
    lam = 1530.0 / 420375.0
    n, pitch = 81, 0.003
    y = (np.arange(n) - (n - 1) / 2) * pitch
    centre = np.stack([np.zeros(n), y, np.zeros(n)], -1)
    small = np.full((n, 2), 1e-5)
    pat = BeamPattern(centre, small, np.zeros(n), np.ones(n), small[:1], np.zeros(1), 2 * np.pi / lam)
    for r in (8.0, 12.0, 20.0, 40.0):
        a = (n * pitch / 2) * np.sqrt(2 / (lam * r))
        s, c = fresnel(a)
        expect = 20 * np.log10(np.hypot(c, s) / a)
        assert pat.near_field_db([[0.0, 0.0, r]])[0] == pytest.approx(expect, abs=0.01)
    assert pat.near_field_db([[0.0, 0.0, 0.0]])[0] == 0.0      # at the array: no NaN, no correction


POINT = """name: ts-point
noise: {{enabled: false}}
signal: {{bandwidth_hz: {bw}}}
targets:
  points:
    - {{range_m: {r}, azimuth_deg: {az}, elevation_deg: {el}, backscatter: {{model: fixed, ts_db: -40}}}}
processing:
  image: {{range_m: [{lo}, {hi}]}}
  detect: {{method: fraction_of_peak, fraction: 0.05}}
"""


@pytest.mark.parametrize("bw", [20000.0, 0.0], ids=["LFM", "CW"])
def test_ts_comp_of_a_point_target_is_unbiased_once_the_near_field_is_compensated(bw):
    """A −40 dB point target at 12 and 20 m, off axis: TS_comp within ±0.05 dB of −40 dB, CW and
    LFM alike. Compensated with the far-field pattern only it reads low by the near field's
    loss, ≈ 0.38 dB at 12 m and 0.14 dB at 20 m (the transmitter's 0.24 m aperture, L²/λ =
    15.8 m): the cause of today's bias, here computed from the geometry and seen in the echo."""
    from acoustics.scene.load import scene_from_text
    from processing.backscatter.calibration import calibration_of
    from processing.backscatter.target_strength import beam_pattern_of, target_strength_db
    for r, az, el in ((12.0, 2.5, 0.15), (20.0, -3.0, -0.2)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = scene_from_text(POINT.format(bw=bw, r=r, az=az, el=el, lo=r - 3, hi=r + 3))
            chain = RecordChain(acoustics.simulate(scene))
            d = chain.detect().table
        i = int(np.argmax(d["amplitude"]))
        cal = calibration_of(chain.tree)
        pat = beam_pattern_of(chain.tree)
        pos = np.stack([d[f"{a}_m"][i:i + 1] for a in "xyz"], -1)
        kw = dict(gain_counts_m=cal.gain_counts_m, absorption_db_per_m=cal.absorption_db_per_m, pattern=pat)
        near = target_strength_db(d["amplitude"][i:i + 1], d["range_m"][i:i + 1], pos, **kw)[1][0]
        far = target_strength_db(d["amplitude"][i:i + 1], d["range_m"][i:i + 1], pos, near_field=False, **kw)[1][0]
        assert near == pytest.approx(-40.0, abs=0.05)
        loss = pat.near_field_db(pos)[0]
        assert loss < -0.1                                 # the near field is there to compensate
        assert far - near == pytest.approx(loss, abs=1e-9)
        assert far == pytest.approx(-40.0 + loss, abs=0.05)


def _fish_scene(pairs: bool, seed: int):
    """Ten fish (TS −50…−34 dB, random phase) 1.2 m apart in range at 13.5–25 m; with ``pairs``,
    each with a partner 0.3–1.0 echo lengths (9.6 cm) farther in range, in the same beam,
    at its own elevation. Physical levels (180 dB source level) and the sea's thermal noise:
    SNR ≈ 50 dB."""
    rng = np.random.default_rng(seed)
    pts, truth = [], []
    for j in range(10):
        r, az, el, ts = 13.5 + 1.2 * j, rng.uniform(-4, 4), rng.uniform(-0.3, 0.3), rng.uniform(-50, -34)
        pts.append(dict(range_m=r, azimuth_deg=az, elevation_deg=el, ts=ts))
        truth.append((r, az, ts))
        if pairs:
            pts.append(dict(range_m=r + rng.uniform(0.3, 1.0) * 0.096, azimuth_deg=az + rng.uniform(-0.7, 0.7),
                            elevation_deg=rng.uniform(-0.3, 0.3), ts=ts + rng.uniform(-3, 3)))
    lines = "\n".join(f"    - {{range_m: {p['range_m']:.4f}, azimuth_deg: {p['azimuth_deg']:.3f}, "
                      f"elevation_deg: {p['elevation_deg']:.3f}, random_phase: true, "
                      f"backscatter: {{model: fixed, ts_db: {p['ts']:.2f}}}}}" for p in pts)
    text = f"""name: fish
seed: {seed}
sonar: {{levels: {{source_level_db: 180.0}}}}
noise: {{enabled: true, model: sea}}
targets:
  points:
{lines}
processing:
  image: {{range_m: [13.0, 26.0]}}
  detect: {{method: rayleigh, pfa_image: 1.0e-6}}
"""
    return text, truth


def _single_targets_near(table, r, az_deg, span_m):
    t = table
    near = ((np.abs(t["range_m"].values - r) <= span_m)
            & (np.abs(np.degrees(t["azimuth_rad"].values) - az_deg) <= 1.6))
    return near & t["single_target"].values


def test_isolated_fish_are_single_targets_with_their_ts():
    """Every isolated fish is a single target (the issue asks ≥ 95 %), its TS_comp within 0.5 dB
    of its TS on average (the noise at SNR ≈ 50 dB allows ≈ 0.05 dB), and nothing else is: the
    range sidelobes and grating ghosts the Rayleigh detector also finds are rejected by rule."""
    from acoustics.scene.load import scene_from_text
    text, truth = _fish_scene(False, 7)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = processing.single_targets(acoustics.simulate(scene_from_text(text)))
    errors = []
    for r, az, ts in truth:
        hit = _single_targets_near(table, r, az, 0.05)
        assert hit.sum() == 1, f"fish at {r} m, {az:.1f}°: {hit.sum()} single targets"
        errors.append(float(table["ts_comp_db"].values[hit][0]) - ts)
    assert np.mean(np.abs(errors)) <= 0.5
    assert int(table["single_target"].sum()) == len(truth)
    rejected = table["rejected_by"].values[~table["single_target"].values]
    assert rejected.size and set(rejected) <= set(RULES)


def test_pairs_closer_than_one_echo_length_are_rejected():
    """Ten pairs of fish in the same beam, 0.3–1.0 echo lengths apart in range (overlapping
    echoes: one envelope, too long or split, its phase drifting from one fish's angle to the
    other's): at least 9 of 10 yield no single target. Pairs closer than ≈ 0.25 echo lengths
    (within the range resolution) are told by their phase alone, and not when their echoes are
    in phase (docs/single_targets.md)."""
    from acoustics.scene.load import scene_from_text
    text, truth = _fish_scene(True, 11)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = processing.single_targets(acoustics.simulate(scene_from_text(text)))
    accepted = sum(bool(_single_targets_near(table, r + 0.05, az, 0.1).any()) for r, az, _ in truth)
    assert accepted <= 1


def test_abacus_targets_writes_every_candidate_with_its_rule(tmp_path):
    """The command: one CSV row per candidate with TS_uncomp/TS_comp, echo length, phase
    deviation and the rule that rejected it (empty for a single target); --accepted-only keeps
    the single targets; a bad criterion in the settings is one line naming the key."""
    from acoustics.scene.load import scene_from_text
    text, truth = _fish_scene(False, 7)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        processing.write_tree(acoustics.simulate(scene_from_text(text)), tmp_path / "fish.nc")
    r = abacus("targets", "fish.nc", "--csv", "all.csv", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["single_targets"] == len(truth)
    rows = list(csv.DictReader(open(tmp_path / "all.csv")))
    assert {"Ping_index", "Target_range", "Angle_azimuth_deg", "Angle_elevation_deg", "Target_x_m",
            "TS_uncomp", "TS_comp", "Echo_length_normalised", "Phase_deviation_deg",
            "Angle_deviation_deg", "Rejected_by"} <= set(rows[0])
    single = [x for x in rows if not x["Rejected_by"]]
    assert len(single) == len(truth) < len(rows)
    assert all(x["Rejected_by"] in RULES for x in rows if x["Rejected_by"])
    (tmp_path / "bad.yaml").write_text("single_target: {maximum_echo_duration: 0.5}\n")
    r = abacus("targets", "fish.nc", "--settings", "bad.yaml", "--csv", "st.csv", "--accepted-only",
               cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr and not (tmp_path / "st.csv").exists()
    assert "maximum_echo_duration" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    # the table keeps the single targets only on request
    table = processing.single_targets(tmp_path / "fish.nc")
    processing.write_targets_csv(table, tmp_path / "st.csv", accepted_only=True)
    assert len(list(csv.DictReader(open(tmp_path / "st.csv")))) == len(truth)


MOVING = """name: moving-point
noise: {{enabled: false}}
sonar:
  pose: {{position_m: [0.0, 0.0, 1.0], boresight: [0.0, 0.0, 1.0], receiver_axis: [0.0, 1.0, 0.0]}}
effects: {{doppler: true}}
targets:
  points:
    - {{frame: world, position_m: [0.0, 0.0, 20.0], velocity_m_s: [0.0, 0.0, {v}],
       backscatter: {{model: fixed, ts_db: -40}}}}
processing:
  image: {{range_m: [16, 22]}}
  detect: {{method: fraction_of_peak, fraction: 0.05}}
"""


def test_a_lone_moving_target_is_a_single_target_up_to_the_stated_radial_speed():
    """A point target moving radially shows a range phase that runs along its echo (the LFM
    pulse's range–Doppler coupling), which the range phase rule alone would take for two
    echoes. Its measured deviation is the pulse's ambiguity-function phase at f_d = 2 v f0 / c,
    computed from the replica alone; the rule allows for targets up to
    ``maximum_radial_speed_m_s`` and rejects faster ones."""
    from acoustics.scene.load import scene_from_text
    from processing.backscatter.echo_criteria import moving_echo_range_phase_deg
    from processing.imaging.compression import RangeFilter
    for v, single_at_default in ((0.7, True), (2.0, False)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = acoustics.simulate(scene_from_text(MOVING.format(v=v)))
            chain = RecordChain(tree)
            found = chain.target_detection()
        i = int(np.argmax(chain.detected().table["amplitude"]))
        rec = chain.record
        rf = RangeFilter.design(rec.replica, n_samples=rec.samples.shape[-1], rate_hz=rec.rate_hz,
                                bandwidth_hz=rec.bandwidth_hz, range_window=chain.settings.image.range_window)
        want = moving_echo_range_phase_deg(rec.replica, rf.spectrum, rf.rate_hz,
                                           2 * v * rec.center_frequency_hz / rec.sound_speed_m_s)
        assert want > 1.0                                    # beyond the fixed 1° limit
        assert found["range_phase_deviation_deg"][i] == pytest.approx(want, rel=0.15)
        assert bool(found["single_target"][i]) is single_at_default, found["rejected_by"][i]
        for v_max, single in ((0.0, False), (v + 0.5, True)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t = RecordChain(tree, {"single_target": {"maximum_radial_speed_m_s": v_max}}).target_detection()
            assert bool(t["single_target"][i]) is single, (v, v_max, t["rejected_by"][i])
            if not single:
                assert t["rejected_by"][i] == "maximum_range_phase_deviation"
