"""Experiments (thesis chapter 6): sweeps, determinism for any number of workers, resuming,
echo integration against a known s_v, target strength from s_v and the counted density, and the
report."""
from __future__ import annotations

import math
import shutil
import warnings

import numpy as np
import pytest
import xarray as xr

import processing
from acoustics import SceneWarning, load_scene
from abacus.experiment import ExperimentError, experiment_plan, parse_sweep, run_experiment
from acoustics.scene import scene_from_text
from acoustics.simulation.run import simulate
from processing.imaging.beamforming import SubarrayGeometry
from processing.imaging.compression import RangeFilter
from processing.base.dataset import read_record
from processing.backscatter.calibration import beam_solid_angle_sr, calibration_of, range_energy_width_m
from processing.backscatter.echo_integration import volume_backscattering
from abacus.evaluate import PER_PING_KEYS

from .conftest import SCENES
from .test_scene import _abacus


def load(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return load_scene(SCENES / name)


def text_scene(text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return scene_from_text(text)


# ------------------------------------------------------------------- sweeps
def test_sweep_forms_and_errors():
    s = parse_sweep("threshold=600:2000:50")
    assert s.values[0] == 600 and s.values[-1] == 2000 and len(s.values) == 29
    assert s.processing_only and s.path == "processing.detect.value"
    assert parse_sweep("noise.sigma_counts=50,100.5").values == (50, 100.5)
    assert not parse_sweep("noise.sigma_counts=50,100").processing_only
    for bad in ("threshold", "threshold=1:2", "threshold=2:1:1", "threshold=1:2:0", "x=a,b", "=1,2"):
        with pytest.raises(ExperimentError, match="KEY=START:STOP:STEP|STEP must"):
            parse_sweep(bad)


def test_sweep_of_an_unknown_key_names_it():
    with pytest.raises(ExperimentError, match="noise.sigma_count.*not a key"):
        experiment_plan(load("default.yaml"), parse_sweep("noise.sigma_count=1,2"))
    with pytest.raises(ExperimentError, match="sigma_counts"):   # validated like a scene file
        experiment_plan(load("default.yaml"), parse_sweep("noise.sigma_counts=-5"))


def test_threshold_sweep_in_thesis_units_keeps_T_over_mu():
    """value_units: thesis means T = value x μ̂ / 139.8: at value = 139.8 the threshold is the
    estimated noise mean itself."""
    sc = load("default.yaml")
    plan = experiment_plan(sc, parse_sweep("threshold=139.8,279.6"))
    tree = simulate(sc, pings=[0])
    from abacus.evaluate import evaluate
    ev = evaluate(tree, [p.settings for p in plan])["per_ping"]
    mu = ev["noise_sigma_counts"][1, 0] * math.sqrt(math.pi / 2)
    assert ev["threshold_counts"][1, 0] == pytest.approx(mu, rel=1e-12)
    assert ev["threshold_counts"][2, 0] == pytest.approx(2 * mu, rel=1e-12)


# ------------------------------------------------------------ determinism, resume
SMALL = """
name: small-experiment
seed: 77
noise: {enabled: true}
targets:
  populations:
    - {kind: uniform_sector, range_m: [14, 24], azimuth_deg: [-6, 6], elevation_deg: [-1, 1],
       count: 12, backscatter: {model: rayleigh}}
processing:
  image: {range_m: [13.0, 25.0]}
  detect: {noise: {source: region, range_m: [13.0, 13.9], estimator: ml}, value_units: noise_mean}
"""


def _per_ping(path):
    with xr.open_dataset(path) as ds:
        return {k: ds[k].values.copy() for k in PER_PING_KEYS}


def test_results_identical_for_one_two_workers_and_a_resume(tmp_path):
    sc = text_scene(SMALL)
    sweep = parse_sweep("threshold=4,6,8")
    kw = dict(pings=range(6), sweep=sweep, figure_pings=1)
    one = _per_ping(run_experiment(sc, tmp_path / "one", workers=1, **kw))
    two = _per_ping(run_experiment(sc, tmp_path / "two", workers=2, **kw))
    # a resume: keep half the finished pings, run again in this process
    parts = sorted((tmp_path / "two" / "parts").glob("*.npz"))
    shutil.copytree(tmp_path / "two", tmp_path / "resumed")
    for p in sorted((tmp_path / "resumed" / "parts").glob("*.npz"))[3:]:
        p.unlink()
    (tmp_path / "resumed" / "results.nc").unlink()
    res_path = run_experiment(sc, tmp_path / "resumed", workers=0, **kw)
    resumed = _per_ping(res_path)
    with xr.open_dataset(res_path) as ds:
        assert ds.attrs["tasks_resumed"] == 3 and ds.attrs["tasks_run"] == len(parts) - 3
    for k in PER_PING_KEYS:
        np.testing.assert_array_equal(one[k], two[k], err_msg=k)
        np.testing.assert_array_equal(one[k], resumed[k], err_msg=k)
    assert np.isfinite(one["count_after"]).all() and np.isfinite(one["true_in_volume"]).all()
    # nMAE of the per-ping counts beside the mean error: Σ|count − true| / Σ true per setting,
    # never below |Σ(count − true)| / Σ true (errors of single pings do not cancel)
    with xr.open_dataset(res_path) as ds:
        for when in ("before", "after"):
            c, t = ds[f"count_{when}"].values, ds["true_in_volume"].values
            want = np.abs(c - t).sum(axis=1) / t.sum(axis=1)
            np.testing.assert_allclose(ds[f"count_nmae_{when}"].values, want, rtol=1e-12)
            assert np.all(ds[f"count_nmae_{when}"].values + 1e-12 >= np.abs((c - t).sum(axis=1)) / t.sum(axis=1))


def test_a_folder_of_another_experiment_is_refused(tmp_path):
    sc = text_scene(SMALL)
    run_experiment(sc, tmp_path / "x", pings=range(1), workers=0, figure_pings=0, report=False)
    with pytest.raises(ExperimentError, match="another experiment.*--restart"):
        run_experiment(sc, tmp_path / "x", pings=range(1), workers=0,
                       sweep=parse_sweep("threshold=4,5"), report=False)
    run_experiment(sc, tmp_path / "x", pings=range(1), workers=0, restart=True,
                   sweep=parse_sweep("threshold=4,5"), figure_pings=0, report=False)


def test_cli_experiment_errors_are_one_line(tmp_path):
    r = _abacus("experiment", str(SCENES / "two_targets.yaml"), "--sweep", "threshold=1:2",
                "-o", str(tmp_path / "e"))
    assert r.returncode == 2 and "Traceback" not in r.stderr and "KEY=START:STOP:STEP" in r.stderr


# ------------------------------------------------------------- echo integration
DENSE = """
name: dense-layer
seed: 4
targets:
  populations:
    - kind: uniform_sector
      range_m: [11, 28]
      azimuth_deg: [-25, 25]
      elevation_deg: [-8, 8]
      density_per_m3: 0.5
      backscatter: {model: fixed, ts_db: -20}
      random_phase: true
pings: {count: 30}
"""


def test_echo_integration_recovers_a_known_s_v():
    """A layer of equal scatterers (σ_bs = 0.01 m², n = 0.5 m⁻³, s_v = 5e-3 m⁻¹) filling the
    whole beam, no noise: the calibrated images integrate to s_v. One ping fluctuates by ~1 dB
    (a few tens of fish in the 0.9° elevation beam); the mean of 30 pings has a standard error of
    ~0.2 dB: tolerance 0.6 dB."""
    tree = processing.image(simulate(text_scene(DENSE)))
    im = processing.images_of(tree)
    rec = read_record(tree)
    cal = calibration_of(tree)
    st = processing.resolve_settings(tree)
    rf = RangeFilter.design(rec.replica, n_samples=rec.samples.shape[-1], rate_hz=rec.rate_hz,
                            bandwidth_hz=rec.bandwidth_hz, range_window=st.image.range_window)
    geo = SubarrayGeometry(rec.element_position_m[rec.image_groups["A"]], st.image.spatial_window)
    sv = volume_backscattering(np.abs(im.image[:, 0]), im.range_m, im.beam_angle_rad,
                               processing.volume_of(tree, st), cal,
                               range_width_m=range_energy_width_m(rf, rec.sound_speed_m_s),
                               solid_angle_sr=beam_solid_angle_sr(cal, geo, im.beam_angle_rad,
                                                                  rec.wavelength_m))
    assert abs(10 * np.log10(sv.mean() / (0.5 * 0.01))) < 0.6


def test_range_energy_width_of_a_rectangular_spectrum():
    """A flat band B (no window, a CW-free LFM replica's |U|² is nearly flat) gives
    h = sinc(B t), ∫ sinc² = 1/B: L_r = c / (2B)."""
    fs, n = 100e3, 8192

    class Flat:   # only what range_energy_width_m reads
        rate_hz = fs
        response = np.where(np.abs(np.fft.fftfreq(n, 1 / fs)) <= 10e3, 1.0, 0.0)
    b = np.count_nonzero(Flat.response) * fs / n
    assert range_energy_width_m(Flat, 1500.0) == pytest.approx(1500.0 / (2 * b), rel=1e-12)


def test_missing_calibration_is_named():
    tree = simulate(load("two_targets.yaml"))
    sonar = tree["Sonar"].ds.drop_vars(["calibration_gain"])
    tree["Sonar"] = xr.DataTree(sonar)
    with pytest.raises(processing.DatasetError, match="calibration_gain"):
        calibration_of(tree)


def test_pelagic_scenario_target_strength_and_threshold_plateau(tmp_path):
    """The pelagic survey (Table 6.6: bounded-Rayleigh TS, noise on, 100 pings):

    - the mean σ_bs from Σ s_v / Σ n is within 1 dB of the true targets' mean σ_bs;
    - sweeping the threshold over the thesis' 600–2000 (its image units, T/μ kept), the threshold
      derived from the noise statistics (correct convention, α = 1e-7) lies on the plateau of
      near-zero mean count error after interferometry (±0.5 targets per ping, the report's
      definition), and the plateau spans several sweep points (thesis §6.3.6, Fig. 6.22)."""
    from abacus.report import derived_in_sweep_units, plateau
    path = run_experiment(load("default.yaml"), tmp_path / "ts", workers=0, figure_pings=0,
                          sweep=parse_sweep("threshold=600:2000:100"), report=False)
    with xr.open_dataset(path) as ds:
        ds.load()
    est, true = float(ds["ts_estimate_db"][0]), float(ds["ts_true_db"][0])
    assert math.isfinite(est) and abs(est - true) < 1.0
    lo, hi = plateau(ds)
    derived = derived_in_sweep_units(ds)
    assert lo <= derived <= hi and hi - lo >= 300


# ------------------------------------------------------------------- the report
def test_report_has_every_figure_with_labelled_axes(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sc = text_scene(SMALL)
    seen = []
    orig = plt.Figure.savefig

    def spy(fig, *a, **k):
        for ax in fig.axes:
            if ax.get_label() == "<colorbar>":
                continue
            seen.append((ax.get_xlabel(), ax.get_ylabel()))
        return orig(fig, *a, **k)

    plt.Figure.savefig = spy
    try:
        run_experiment(sc, tmp_path / "r", pings=range(3), sweep=parse_sweep("threshold=4,6"),
                       workers=0, figure_pings=1)
    finally:
        plt.Figure.savefig = orig
    page = (tmp_path / "r" / "report.html").read_text()
    for name in ("counts", "count_error", "noise_pdf", "sweep", "density", "ts"):
        assert (tmp_path / "r" / "figures" / f"{name}.png").exists(), name
    assert page.count("data:image/png;base64,") == 7      # six figures + one fan-beam image
    assert seen and all(x and y for x, y in seen)
    # every axis label states a unit in parentheses, or is a pure index
    for x, y in seen:
        for lab in (x, y):
            assert "(" in lab or lab == "ping index", lab


# ------------------------------------------------------------- tracked runs
def test_tracked_runs_score_as_abacus_track_and_keep_every_ping(tmp_path):
    """With --track-pings an experiment simulates runs of consecutive pings and scores their
    tracks: each run's numbers are those of `abacus track` on a simulation of the same pings
    (the tracker's, not a copy), the nMAE of the track counts adds the runs' errors without
    letting them cancel, and a ping's simulation does not depend on the run it was simulated in."""
    from processing.tracking.tracks import track_summary

    from abacus.results import TRACK_KEYS
    sc = load("school_tracks.yaml")
    tracked = run_experiment(sc, tmp_path / "t", pings=range(12), track_pings=6, workers=0,
                             figure_pings=0, report=False)
    alone = run_experiment(sc, tmp_path / "p", pings=range(12), workers=0, figure_pings=0,
                           report=False)
    settings = experiment_plan(sc, None)[0].settings
    with xr.open_dataset(tracked) as ds:
        assert list(ds["run_first_ping"].values) == [0, 6]
        for r, first in enumerate((0, 6)):
            want = track_summary(processing.track(simulate(sc, pings=range(first, first + 6)),
                                                  settings))["summary"]
            assert want["true_passages"] > 0
            for k in TRACK_KEYS:
                got = float(ds[f"run_{k}"].values[0, r])
                assert got == pytest.approx(float(want[k]), abs=1e-12), k
        c, t = ds["run_counted_passages"].values[0], ds["run_true_passages"].values[0]
        assert float(ds["track_count_nmae"].values[0]) == pytest.approx(np.abs(c - t).sum() / t.sum(), abs=1e-12)
        assert 0 <= float(ds["hota_mean"].values[0]) <= 1
        pp = {k: ds[k].values for k in PER_PING_KEYS}
    # the simulation of a ping does not depend on the run it was simulated in: its truth is the
    # same; the detector's noise estimate (and so threshold and counts) pools a record's pings,
    # as `abacus run` does, so a run of six pings may set a ping's threshold a little apart
    one = _per_ping(alone)
    for k in ("true_in_volume", "true_in_span", "true_density_per_m3", "true_sigma_bs_m2"):
        np.testing.assert_array_equal(pp[k], one[k], err_msg=k)


@pytest.mark.parametrize("bad", [0, 1, 13, 2.5, True])
def test_track_pings_outside_the_experiment_is_refused(tmp_path, bad):
    sc = text_scene(SMALL)
    with pytest.raises(ExperimentError, match="--track-pings must be a whole number of pings from 2"):
        run_experiment(sc, tmp_path / "x", pings=range(12), track_pings=bad, workers=0, report=False)
    assert not (tmp_path / "x").exists()


def test_runs_without_a_fish_or_a_track_are_left_out_of_the_score_means(tmp_path):
    """A run where nothing passes scores HOTA 0 and LocA 1 by TrackEval's convention: nothing to
    score, so it does not pull the means; with no run left they are NaN, and so is the nMAE
    (no true passage)."""
    sc = text_scene("name: nobody-passes\nseed: 5\nnoise: {enabled: true}\n")
    path = run_experiment(sc, tmp_path / "e", pings=range(4), track_pings=2, workers=0,
                          figure_pings=0, report=False)
    with xr.open_dataset(path) as ds:
        t, c = ds["run_true_passages"].values, ds["run_counted_passages"].values
        assert ((t == 0) & (c == 0)).all()
        assert (ds["run_hota"].values == 0).all()         # what the tracker's own score says
        assert np.isnan(ds["hota_mean"].values).all() and np.isnan(ds["track_count_nmae"].values).all()
