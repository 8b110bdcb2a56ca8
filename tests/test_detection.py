"""Noise estimate, thresholds, CFAR, peaks, 3-D location, counting and scoring (thesis ch. 5–6)."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
from scipy import stats

import processing
from acoustics import SceneWarning, load_scene
from acoustics.scene import scene_from_text
from acoustics.simulation.run import simulate
from processing.base.counting_volume import CountingVolume
from processing.detection.locate import locate
from processing.detection.noise import NoiseEstimateError, rayleigh_fit
from processing.detection.scoring import match
from processing.detection.thresholds import (ca_cfar_factor, cell_pfa, cfar_threshold, os_cfar_factor,
                                   rayleigh_threshold)

from .conftest import LAMBDA_M, ROOT, SCENES


def scene(name_or_text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        if name_or_text.endswith(".yaml"):
            return load_scene(SCENES / name_or_text)
        return scene_from_text(name_or_text)


# ---------------------------------------------------------------- thresholds
def test_thesis_convention_reproduces_its_numbers():
    """Table 6.5: μ = 139.8, α = 1e-7, N = 17802 -> P_cell = 9.05e-4 and T ≈ 656 (eq. 5.4, 5.9)."""
    p = cell_pfa(1e-7, 23 * 774, convention="thesis")
    assert p == pytest.approx(9.05e-4, rel=2e-3)
    sigma = 139.8 / math.sqrt(math.pi / 2)
    assert rayleigh_threshold(sigma, p, convention="thesis") == pytest.approx(656, abs=1.0)


def test_correct_convention_gives_about_800():
    """1 − (1 − α)^(1/N) ≈ α/N = 5.6e-12 and T = σ√(−2 ln P) ≈ 800 for μ = 139.8."""
    p = cell_pfa(1e-7, 17802)
    assert p == pytest.approx(1e-7 / 17802, rel=1e-6)
    t = rayleigh_threshold(139.8 / math.sqrt(math.pi / 2), p)
    assert t == pytest.approx(800, abs=5)
    # the threshold holds its promise: P(Rayleigh > T) = P_cell exactly
    assert stats.rayleigh(scale=139.8 / math.sqrt(math.pi / 2)).sf(t) == pytest.approx(p, rel=1e-9)


def test_threshold_inputs_are_checked():
    with pytest.raises(ValueError, match="pfa_image"):
        cell_pfa(0.0, 100)
    with pytest.raises(ValueError, match="noise scale"):
        rayleigh_threshold(0.0, 1e-3)
    with pytest.raises(ValueError, match="noise scale"):
        rayleigh_threshold(float("nan"), 1e-3)


@pytest.mark.parametrize("kind", ["ca", "os"])
def test_cfar_holds_its_false_alarm_rate_on_exponential_noise(kind, rng):
    """On Rayleigh noise (any level, varying with range) CFAR exceeds its threshold at P_fa."""
    n_r, n_b = 2000, 64
    level = np.linspace(1, 20, n_r)[:, None]  # noise that varies with range: CFAR's reason to be
    mag = level * np.abs(rng.normal(size=(n_r, n_b)) + 1j * rng.normal(size=(n_r, n_b))) / math.sqrt(2)
    pfa = 1e-3
    thr, n, a = cfar_threshold(mag, pfa=pfa, kind=kind, guard=(2, 1), training=(8, 3))
    rate = np.mean(mag > thr)
    assert pfa / 2 < rate < 2 * pfa, rate
    if kind == "ca":
        assert a == pytest.approx(ca_cfar_factor(n, pfa))


def test_os_cfar_factor_solves_rohlings_equation():
    n, k, pfa = 48, 36, 1e-4
    a = os_cfar_factor(n, k, pfa)
    prod = np.prod([(n - i) / (n - i + a) for i in range(k)])
    assert prod == pytest.approx(pfa, rel=1e-9)


def test_cfar_on_a_zero_image_has_no_noise_and_says_so():
    thr, _, _ = cfar_threshold(np.zeros((50, 10)), pfa=1e-3, guard=(1, 1), training=(4, 2))
    assert np.all(np.isinf(thr))


# --------------------------------------------------------------------- noise
def test_rayleigh_fit_recovers_sigma_and_flags_non_rayleigh(rng):
    x = stats.rayleigh(scale=3.0).rvs(200_000, random_state=rng)
    for est in ("ml", "median"):
        f = rayleigh_fit(x, estimator=est)
        assert f.sigma == pytest.approx(3.0, rel=0.01)
        assert f.mu == pytest.approx(3.0 * math.sqrt(math.pi / 2), rel=0.01)
        assert f.rayleigh_like
    bad = np.abs(rng.normal(size=100_000)) ** 3  # not Rayleigh
    assert not rayleigh_fit(bad).rayleigh_like
    with pytest.raises(NoiseEstimateError, match="noise-free"):
        rayleigh_fit(np.zeros(100))
    with pytest.raises(NoiseEstimateError, match="NaN"):
        rayleigh_fit(np.array([1.0, np.nan]))


@pytest.fixture(scope="module")
def noise_only():
    return processing.image(simulate(scene("noise_only.yaml"), pings=range(12)))


def test_noise_only_mean_matches_sigma_and_the_filter_gains(noise_only):
    im = processing.images_of(noise_only)
    mags = np.abs(im.image)
    fit = rayleigh_fit(mags, estimator="ml", decimate=(Ellipsis, slice(None, None, 4), slice(None, None, 4)))
    sigma_ch = 126.68
    expected_mu = sigma_ch * math.sqrt(im.noise_power_gain) * math.sqrt(math.pi / 2)
    assert fit.mu == pytest.approx(expected_mu, rel=0.02)
    assert fit.rayleigh_like
    # the gain is what the filters predict: matched filter (Hann-shaped |U|², Hamming window,
    # noise in the fs/2 band) times the Hamming beamformer Σw²/(Σw)²
    from processing.imaging.compression import window
    w = window("hamming", 8)
    assert im.noise_power_gain / (np.sum(w**2) / np.sum(w) ** 2) == pytest.approx(0.0137, rel=0.1)


def test_noise_only_false_alarm_rate_per_cell(noise_only):
    """At the threshold derived for P_fa,cell = 1e-3 the measured exceedance rate of noise cells
    is within a factor 2 of 1e-3, over more than a million cells."""
    im = processing.images_of(noise_only)
    mags = np.abs(im.image[:, 0])
    assert mags.size >= 1_000_000
    fit = rayleigh_fit(mags, estimator="median")
    t = rayleigh_threshold(fit.sigma, 1e-3)
    rate = float(np.mean(mags > t))
    assert 0.5e-3 < rate < 2e-3, rate


def test_derived_threshold_on_noise_only_rarely_false_alarms(noise_only):
    """The full detector on noise: α = 1e-7 per image means essentially no detections."""
    out = processing.detect(noise_only)
    det = processing.detections_of(out)
    assert det["in_span"].sum() <= 1
    assert out["Processing/Detections"].ds.attrs["pfa_cell"] == pytest.approx(5.6e-12, rel=0.05)


def test_zero_noise_with_a_noise_derived_threshold_is_an_error():
    tree = simulate(scene("name: z\n"))  # nothing at all: zero image
    with pytest.raises(NoiseEstimateError, match="noise-free"):
        processing.detect(tree)


def test_empty_image_with_a_relative_threshold_detects_nothing_without_error():
    tree = simulate(scene("name: z\nprocessing:\n  detect: {method: fraction_of_peak}\n"))
    det = processing.detections_of(processing.detect(tree))
    assert det["range_m"].size == 0
    counts = processing.counts_of(processing.count(tree))
    assert counts["count_after"].values.tolist() == [0]


# -------------------------------------------------------------- 3-D location
def test_locate_inverts_the_exact_geometry(rng):
    """Forward model (exact distances) -> locate -> the same point, to micrometres."""
    t = np.array([0.0, 0.0, 0.0])
    a = np.array([-0.00375, -0.01205, 0.0])
    b = np.array([0.00375, 0.01205, 0.0])
    n = 500
    r = rng.uniform(11, 60, n)
    az = rng.uniform(-0.12, 0.12, n)
    el = rng.uniform(-0.02, 0.02, n)
    p = np.stack([r * np.cos(el) * np.sin(az), r * np.sin(el), r * np.cos(el) * np.cos(az)], -1)
    ra, rb, rt = (np.linalg.norm(p - v, axis=1) for v in (a, b, t))
    tau = (rt + ra) / 1530.0
    sin_th = (p - a)[:, 0] / ra
    psi = -2 * np.pi / LAMBDA_M * (ra - rb)
    got = locate(tau, np.arcsin(sin_th), psi, transmitter_m=t, center_a_m=a, center_b_m=b,
                 sound_speed_m_s=1530.0, wavelength_m=LAMBDA_M)
    assert np.abs(got - p).max() < 1e-6


def test_locate_is_finite_for_any_phase():
    got = locate(np.full(5, 0.03), np.zeros(5), np.linspace(-np.pi, np.pi, 5),
                 transmitter_m=np.zeros(3), center_a_m=[0, -0.012, 0], center_b_m=[0, 0.012, 0],
                 sound_speed_m_s=1530.0, wavelength_m=LAMBDA_M)
    assert np.all(np.isfinite(got))


def test_isolated_targets_are_located_within_resolution():
    """SNR >= 20 dB, isolated targets: |range error| < 2 cm, cross-range errors below the
    azimuth/elevation resolution times range."""
    pts = []
    for i, (az, el) in enumerate([(-4, 0.3), (-2.5, -0.2), (-1, 0.1), (0.5, -0.35), (2, 0.25),
                                  (3.5, 0.0), (4.5, -0.1), (1.2, 0.38)]):
        pts.append(f"    - {{range_m: {14 + 1.4 * i}, azimuth_deg: {az}, elevation_deg: {el}}}")
    sc = scene("name: loc\nseed: 5\nnoise: {enabled: true, sigma_counts: 10.0}\n"
               "targets:\n  points:\n" + "\n".join(pts) + "\npings: {count: 5}\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # strong targets' sidelobes make the cells less Rayleigh
        tree = processing.detect(simulate(sc))
    det = processing.detections_of(tree)
    gt = tree["Vendor_specific"].ds
    tp = np.stack([gt[f"target_{a}"].values for a in "xyz"], -1)
    tping = gt["target_ping_index"].values
    pds = tree["Processing"].ds
    daz = pds.attrs["azimuth_resolution_rad"]
    dsel = np.radians(0.86)  # the transmitter's elevation beamwidth: the resolution cell's height
    n_checked = 0
    for p in range(5):
        k = det["ping"] == p
        pos = np.stack([det["x_m"][k], det["y_m"][k], det["z_m"][k]], -1)
        for q in tp[tping == p]:
            d = np.linalg.norm(pos - q, axis=1)
            j = int(np.argmin(d))
            assert det["snr_db"][k][j] > 20  # the condition of the claim
            rq = np.linalg.norm(q)
            assert abs(np.linalg.norm(pos[j]) - rq) < 0.02
            assert abs(math.atan2(pos[j][0], pos[j][2]) - math.atan2(q[0], q[2])) * rq < daz * rq
            el_d = math.atan2(pos[j][1], math.hypot(pos[j][0], pos[j][2]))
            el_q = math.atan2(q[1], math.hypot(q[0], q[2]))
            assert abs(el_d - el_q) * rq < dsel * rq
            n_checked += 1
    assert n_checked == 40


# ------------------------------------------------------------------ counting
def test_counting_volume_of_the_thesis_is_13p8_m3():
    v = CountingVolume((13.0, 26.0), math.radians(5.15), math.radians(0.43))
    assert v.volume_m3 == pytest.approx(13.8, abs=0.05)
    assert v.contains([[0, 0, 20.0]])[0] and not v.contains([[0, 0.2, 20.0]])[0]


def test_counting_volume_from_a_dataset_uses_the_transmitter_beam():
    tree = processing.count(simulate(scene("two_targets.yaml")))
    assert tree["Processing/Counts"].ds.attrs["counting_volume_m3"] == pytest.approx(13.8, rel=0.01)


def test_two_targets_in_one_cell_are_never_both_counted():
    """Echoes 1 cm apart interfere; the interferometric phase of the cell is a mixture (thesis
    §4.7: one target per cell is assumed), so the pair is not counted as two, and the scoring
    attributes the misses to the shared cell. Nothing is NaN."""
    sc = scene("name: pair\ntargets:\n  points:\n    - {range_m: 20.0, azimuth_deg: 0.5, elevation_deg: 0.1}\n"
               "    - {range_m: 20.01, azimuth_deg: 0.9, elevation_deg: -0.1}\n"
               "processing:\n  detect: {method: fraction_of_peak}\n")
    tree = processing.count(simulate(sc))
    c = processing.counts_of(tree)
    det = processing.detections_of(tree)
    assert c["true_in_volume"][0] == 2 and c["count_after"][0] < 2
    assert c["misses_after"][0] >= 1 and c["shared_cell_misses"][0] == c["misses_after"][0]
    # snr_db is NaN by contract when no noise level was estimated (a relative threshold here)
    assert all(np.all(np.isfinite(v)) for k, v in det.items() if v.dtype.kind == "f" and k != "snr_db")
    assert np.all(np.isnan(det["snr_db"]))


def test_target_on_the_image_edge_is_detected():
    sc = scene("name: edge\ntargets:\n  points:\n    - {range_m: 13.02, azimuth_deg: 0.0, elevation_deg: 0}\n"
               "processing:\n  detect: {method: fraction_of_peak}\n")
    det = processing.detections_of(processing.detect(simulate(sc)))
    assert det["range_m"].size == 1 and abs(det["range_m"][0] - 13.02) < 0.05


SMALL_BASELINE = """
name: short-baseline
seed: 3
noise: {enabled: true}
sonar:
  preset: null
  mode: interferometric
  transmitter:
    line: {count: 16, pitch_m: 0.012, axis: y, width_m: 0.02, height_m: 0.012}
  receiver:
    A:
      line: {count: 8, pitch_m: 0.015, axis: x, width_m: 0.012, height_m: 0.0015, center_m: [0, -0.0008, 0]}
    B:
      line: {count: 8, pitch_m: 0.015, axis: x, width_m: 0.012, height_m: 0.0015, center_m: [0, 0.0008, 0]}
targets:
  points:
    - {range_m: 20.0, azimuth_deg: 0.0, elevation_deg: 30.0}
processing:
  detect: {method: fraction_of_peak}
"""


def test_elevation_beyond_the_arcsin_range_is_clipped_and_flagged():
    """With a baseline shorter than λ/2 (1.6 mm), noise pushes |ψ| past 2π b/λ: the arcsin
    argument exceeds 1 in those cells. They are clipped and flagged; nothing is NaN."""
    tree = processing.detect(processing.image(simulate(scene(SMALL_BASELINE))))
    im = processing.images_of(tree)
    assert np.all(np.isfinite(im.elevation_rad))
    assert 0 < im.elevation_clipped.mean() < 0.5
    assert np.all(np.abs(im.elevation_rad[im.elevation_clipped.astype(bool)]) <= np.pi / 2 + 1e-6)
    det = processing.detections_of(tree)
    assert det["range_m"].size >= 1
    assert np.all(np.isfinite(det["elevation_rad"])) and np.all(np.isfinite(det["z_m"]))


def test_matching_gate_and_hungarian_assignment():
    s = match([20.0, 20.0], [0.0, 0.05], [20.0, 20.0, 25.0], [0.0, 0.05, 0.0], dr=0.07, dtheta=0.04)
    assert (s.hits, s.misses, s.false_alarms) == (2, 1, 0)
    s = match([20.5], [0.0], [20.0], [0.0], dr=0.07, dtheta=0.04)  # 7 cells away: no match
    assert (s.hits, s.misses, s.false_alarms) == (0, 1, 1)


# ------------------------------------------------------------- the scenarios
def test_counting_algorithm_scenario_table_6_1():
    """15 unit targets inside the counting volume, no noise, 100 pings, 15 % threshold."""
    c = processing.count_summary(processing.count(simulate(scene("counting_algorithm.yaml"))))["summary"]
    assert c["pings"] == 100
    assert c["mean_abs_error_after"] <= 0.5
    # undercounts come from targets that share a resolution cell
    assert c["total_misses_after"] > 0
    assert c["total_shared_cell_misses"] >= 0.8 * c["total_misses_after"]


def test_position_scenario_table_6_4():
    """100 unit targets in 215.6 m³: counts before interferometry overestimate; after, the mean
    error is within ±0.3 per ping."""
    c = processing.count_summary(processing.count(simulate(scene("position.yaml"))))["summary"]
    assert c["error_before"]["mean"] > 2.0
    assert abs(c["error_after"]["mean"]) <= 0.3
    assert c["error_after"]["std"] < c["error_before"]["std"]


# ----------------------------------------------------------------------- CLI
def test_abacus_count_json_and_csv(tmp_path):
    tree = simulate(scene("two_targets.yaml"))
    path = processing.write_tree(tree, tmp_path / "two.nc")
    r = subprocess.run([sys.executable, "-m", "abacus.cli", "count", str(path), "--json",
                        "--csv", str(tmp_path / "det.csv"), "--settings", str(tmp_path / "s.yaml")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "no such file" in r.stderr and "Traceback" not in r.stderr
    (tmp_path / "s.yaml").write_text("detect: {method: fraction_of_peak, fraction: 0.15}\n")
    r = subprocess.run([sys.executable, "-m", "abacus.cli", "count", str(path), "--json",
                        "--csv", str(tmp_path / "det.csv"), "--settings", str(tmp_path / "s.yaml")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["summary"]["pings"] == 1 and out["pings"][0]["count_after"] == 2
    lines = (tmp_path / "det.csv").read_text().splitlines()
    assert lines[0].startswith("ping,") and len(lines) == 3


def test_abacus_count_on_a_file_that_is_not_a_dataset(tmp_path):
    bad = tmp_path / "bad.nc"
    bad.write_text("not netcdf")
    r = subprocess.run([sys.executable, "-m", "abacus.cli", "count", str(bad)], capture_output=True,
                       text=True, cwd=ROOT)
    assert r.returncode == 2 and str(bad) in r.stderr and "Traceback" not in r.stderr
