"""Tracking across pings (processing/tracking/filters.py, processing/tracking/tracks.py) and beam-compensated TS
(processing/backscatter/target_strength.py): ground truth recovered on cases simple enough to reason about."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import acoustics
import processing
from acoustics.scene import SceneWarning, scene_from_text
from processing.backscatter.calibration import calibration_of
from processing.backscatter.target_strength import beam_pattern_of, target_strength_db
from processing.tracking.filters import cv_matrices, measurement_covariance, track_detections
from processing.backscatter.single_targets import single_targets
from processing.tracking.tracks import track, tracks_of


def _quiet(text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return scene_from_text(text)


def _iso(n, sd_m):
    return np.repeat((sd_m**2 * np.eye(3))[None], n, axis=0)


def test_kalman_recovers_a_straight_track_and_its_speed():
    """A target at 0.5 m/s measured with 1 cm noise for 40 pings: the smoothed velocity is within
    the Cramér–Rao-like spread σ √12 / (T √N) ≈ 1 mm/s of the truth (tolerance 5 σ)."""
    rng = np.random.default_rng(1)
    t = np.arange(40) * 0.1
    truth = np.c_[0.5 * t, 0.1 * t, np.full(40, 18.0)]
    z = truth + rng.normal(0, 0.01, truth.shape)
    tracks = track_detections(np.arange(40), t, z, _iso(40, 0.01), accel_sd_m_s2=0.01)
    assert len(tracks) == 1
    v = np.mean(np.array(tracks[0].smoothed)[:, 3:], axis=0)
    bound = 0.01 * np.sqrt(12) / (t[-1] * np.sqrt(40))
    np.testing.assert_allclose(v, [0.5, 0.1, 0.0], atol=5 * bound + 1e-3)


def test_two_fish_crossing_keep_their_identities():
    """Two fish cross (same point at the middle ping) on straight paths 90° apart: with the
    velocity in the state the assignment after the crossing follows the motion."""
    t = np.arange(21) * 0.2
    a = np.c_[-1 + 0.5 * t, np.zeros(21), np.full(21, 18.0)]
    b = np.c_[np.zeros(21), -1 + 0.5 * t, np.full(21, 18.0)]
    pings = np.r_[np.arange(21), np.arange(21)]
    pos = np.r_[a, b]
    who = np.r_[np.zeros(21, int), np.ones(21, int)]
    tracks = track_detections(pings, t, pos, _iso(42, 0.01), accel_sd_m_s2=0.05)
    assert len(tracks) == 2
    for tr in tracks:
        members = {int(who[j]) for j in tr.detection if j >= 0}
        assert len(members) == 1, "a track swapped fish at the crossing"
        assert len(tr.pings) == 21


def test_a_missed_detection_is_coasted_not_a_new_track():
    t = np.arange(20) * 0.25
    pos = np.c_[0.3 * t, np.zeros(20), np.full(20, 18.0)]
    keep = np.ones(20, bool)
    keep[9] = False                                   # missed in the middle of the track
    tracks = track_detections(np.flatnonzero(keep), t, pos[keep], _iso(19, 0.01))
    assert len(tracks) == 1
    tr = tracks[0]
    assert tr.pings == list(range(20)) and tr.detection[9] == -1
    # the coasted position lies on the straight line (within 3 cm)
    np.testing.assert_allclose(tr.smoothed[9][:3], pos[9], atol=0.03)


def test_a_fish_leaving_and_reentering_is_two_tracks_and_nothing_is_nan():
    """Gone for more than max_misses pings: a new passage, a new track; a single stray detection
    never becomes a track (no confirmation) and nothing is NaN."""
    t = np.arange(30) * 0.25
    pos = np.c_[0.3 * t, np.zeros(30), np.full(30, 18.0)]
    keep = np.ones(30, bool)
    keep[10:16] = False
    p = list(np.flatnonzero(keep)) + [5]
    z = np.r_[pos[keep], [[3.0, 3.0, 15.0]]]
    tracks = track_detections(np.array(p), t, z, _iso(len(p), 0.01), max_misses=2)
    assert len(tracks) == 2
    assert all(np.all(np.isfinite(np.array(tr.smoothed))) for tr in tracks)
    assert track_detections(np.array([3]), t, [[0, 0, 18.0]], _iso(1, 0.01)) == []
    assert track_detections(np.array([], int), t, np.zeros((0, 3)), np.zeros((0, 3, 3))) == []


def test_alpha_beta_tracks_a_straight_path():
    t = np.arange(30) * 0.25
    pos = np.c_[0.4 * t, -0.2 * t, np.full(30, 18.0)]
    tracks = track_detections(np.arange(30), t, pos, _iso(30, 0.01), method="alpha_beta")
    assert len(tracks) == 1
    np.testing.assert_allclose(tracks[0].x[-1][3:], [0.4, -0.2, 0.0], atol=0.01)


def test_process_noise_is_the_white_acceleration_model():
    """Q = q [[dt³/3, dt²/2], [dt²/2, dt]] (Bar-Shalom et al. 2001, eq. 6.2.2-12)."""
    F, Q = cv_matrices(0.5, 2.0)
    assert F[0, 3] == 0.5 and Q[0, 0] == pytest.approx(4 * 0.5**3 / 3)
    assert Q[0, 3] == pytest.approx(4 * 0.5**2 / 2) and Q[3, 3] == pytest.approx(4 * 0.5)


def test_measurement_covariance_follows_the_geometry():
    """At boresight the range error is along z, azimuth along x (r σ_θ), elevation along y
    (r σ_φ); σ = δ/√(2 SINR), σ_φ = λ / (2π b √SINR), SINR = 1/(1/SNR + 1/SIR)."""
    kw = dict(range_resolution_m=0.07, azimuth_resolution_rad=0.04, wavelength_m=0.00364,
              baseline_m=0.0241)
    for snr_db, sir_db in ((20.0, 100.0), (40.0, 20.0)):
        C = measurement_covariance([20.0], [0.0], [0.0], [snr_db], interference_db=sir_db, **kw)[0]
        sinr = 1 / (10 ** (-snr_db / 10) + 10 ** (-sir_db / 10))
        assert np.sqrt(C[2, 2]) == pytest.approx(0.07 / np.sqrt(2 * sinr))
        assert np.sqrt(C[0, 0]) == pytest.approx(20 * 0.04 / np.sqrt(2 * sinr))
        assert np.sqrt(C[1, 1]) == pytest.approx(20 * 0.00364 / (2 * np.pi * 0.0241) / np.sqrt(sinr))
    # a strong echo is limited by the interference, not the noise: 60 dB SNR reads as ≈ 20 dB
    strong = measurement_covariance([20.0], [0.0], [0.0], [60.0], interference_db=20.0, **kw)[0]
    weak = measurement_covariance([20.0], [0.0], [0.0], [20.0], interference_db=100.0, **kw)[0]
    np.testing.assert_allclose(strong, weak, rtol=0.02)
    assert np.all(np.isfinite(measurement_covariance([20.0], [0.0], [np.pi / 2], [np.nan], **kw)))


def test_sidelobes_of_a_strong_echo_are_not_single_targets():
    r = np.array([18.0, 18.0, 18.1, 18.0, 20.0])
    az = np.radians([1.0, 6.4, 1.0, -3.0, 6.4])
    amp = np.array([1000.0, 30.0, 5.0, 500.0, 1.0])          # −30.5, −46 dB; a fish −6 dB; far
    keep = single_targets(np.zeros(5, int), r, az, amp, range_resolution_m=0.067,
                          azimuth_resolution_rad=np.radians(2.4), sidelobe_db=20.0)
    assert keep.tolist() == [True, False, False, True, True]


SPHERE = """name: ts
noise: {enabled: false}
targets:
  points:
    - {range_m: 20.0, azimuth_deg: %s, elevation_deg: %s, backscatter: {model: fixed, ts_db: -40}}
pings: {count: 1}
"""


@pytest.mark.parametrize("az, el", [(0.0, 0.0), (3.0, 0.0), (6.0, 0.2), (0.0, 0.35), (-4.0, -0.3)])
def test_compensated_ts_of_a_target_off_axis_is_its_ts(az, el):
    """A −40 dB target anywhere in the main lobe (two-way pattern down to −7 dB) reads −40 dB
    within 0.5 dB once compensated at its located angles: the pattern is computed from the
    dataset's element geometry, independently of the simulator."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")           # no noise: the threshold's noise fit warns
        tree = processing.detect(acoustics.simulate(_quiet(SPHERE % (az, el))))
    d = processing.detections_of(tree)
    i = int(np.argmax(d["amplitude"].values))
    cal = calibration_of(tree)
    pos = np.stack([d[k].values[i:i + 1] for k in ("x_m", "y_m", "z_m")], -1)
    ts_u, ts_c, pat = target_strength_db(d["amplitude"].values[i:i + 1], d["range_m"].values[i:i + 1],
                                         pos, gain_counts_m=cal.gain_counts_m,
                                         absorption_db_per_m=cal.absorption_db_per_m,
                                         pattern=beam_pattern_of(tree))
    assert ts_c[0] == pytest.approx(-40.0, abs=0.5)
    assert ts_u[0] == pytest.approx(-40.0 + pat[0], abs=0.5)


def test_one_fish_passing_is_one_track_with_its_speed_and_ts():
    """The fish of scenes/fish_passing.yaml (0.5 m/s across the fan, TS −41 to −35 dB): one
    track, the one true passage, its speed within 2 cm/s and its mean TS within 1 dB."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = acoustics.load_scene("fish_passing")
        ds = tracks_of(track(acoustics.simulate(scene)))
    assert ds.attrs["track_count"] == 1 and ds.attrs["true_passages"] == 1
    assert ds.attrs["idf1"] == pytest.approx(1.0)
    assert abs(ds.attrs["speed_error_mean"]) < 0.02
    assert abs(ds.attrs["ts_error_mean"]) < 1.0
    assert float(ds["track_speed"].values[0]) == pytest.approx(0.5, abs=0.02)


def test_abacus_track_writes_tracks_csv_and_plots_and_refuses_a_bad_setting(tmp_path):
    """The command a user runs: one fish passing gives one counted track in the JSON, a CSV row
    per track with the documented columns, two figures; a bad tracking setting is one line."""
    import csv
    import json

    from .test_cli import abacus
    r = abacus("simulate", "fish_passing", "-o", "fp.nc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = abacus("track", "fp.nc", "--json", "--csv", "t.csv", "--plots", "figs", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["summary"]["track_count"] == 1 and out["summary"]["true_passages"] == 1
    counted = [t for t in out["tracks"] if t["in_counting_volume"]]
    assert len(counted) == 1 and abs(counted[0]["speed_m_s"] - 0.5) < 0.02
    assert abs(counted[0]["heading_deg"] % 360) < 3 or abs(counted[0]["heading_deg"] - 360) < 3  # +x
    rows = list(csv.DictReader(open(tmp_path / "t.csv")))
    assert len(rows) == len(out["tracks"]) and {"ts_mean_db", "speed_m_s", "num_targets"} <= set(rows[0])
    assert sorted(p.name for p in (tmp_path / "figs").iterdir()) == ["track_ts.png", "tracks.png"]
    (tmp_path / "bad.yaml").write_text("track: {gate_probability: 1.5}\n")
    r = abacus("track", "fp.nc", "--settings", "bad.yaml", cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "gate_probability" in r.stderr and len(r.stderr.strip().splitlines()) == 1


LOUD = """name: loud
sonar:
  pose: {position_m: [0.0, 0.0, 1.0], boresight: [0.0, 0.0, 1.0], receiver_axis: [0.0, 1.0, 0.0]}
  levels: {source_level_db: 210.0}
noise: {enabled: true, model: sea}
targets:
  points:
    - {range_m: 18.0, azimuth_deg: -2.5, elevation_deg: 0.0, backscatter: {model: fixed, ts_db: -25}}
pings: {count: 3}
processing:
  image: {range_m: [13.0, 26.0]}
  detect: {method: rayleigh, pfa_image: 1.0e-6, noise: {source: region, range_m: [13.0, 15.5], estimator: ml}}
"""


def test_far_range_sidelobes_of_a_strong_echo_are_below_the_ts_threshold():
    """An echo ~100 dB above the noise (TS −25 dB at 18 m, physical levels) is detected again in
    the far range sidelobes of the Hamming range window (≈ −80 dB, metres away, at its azimuth).
    Their compensated TS is ≈ 80 dB below the target's, far below the −70 dB single-target
    threshold, so they are not tracked; the target itself reads −25 ± 0.5 dB."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = processing.detect(acoustics.simulate(_quiet(LOUD)))
    d = processing.detections_of(tree)
    cal = calibration_of(tree)
    pos = np.stack([d[k].values for k in ("x_m", "y_m", "z_m")], -1)
    _, ts_c, _ = target_strength_db(d["amplitude"].values, d["range_m"].values, pos,
                                    gain_counts_m=cal.gain_counts_m,
                                    absorption_db_per_m=cal.absorption_db_per_m,
                                    pattern=beam_pattern_of(tree))
    far = np.abs(d["range_m"].values - 18.0) > 1.0
    assert far.any(), "no far range sidelobe detected: the premise of the threshold is gone"
    assert np.all(ts_c[far][np.isfinite(ts_c[far])] < -70.0)
    assert np.nanmax(ts_c) == pytest.approx(-25.0, abs=0.5)
    ds = tracks_of(track(tree))
    assert ds.sizes["track"] == 1 and ds.attrs["track_count"] == 1
