"""The processing chain over a record a few pings at a time, the geometry caches and the run
folder: same numbers however the work is cut, nothing half-written."""
from __future__ import annotations

import json
import subprocess
import sys
import warnings
from dataclasses import replace

import numpy as np
import pytest

import acoustics
import processing
from acoustics.scene import SceneWarning
import processing.chain as chain
from processing.chain import detect_record, record_pings
from processing.detection.detect import detect_all, fit_noise_cells, noise_cells
from processing.imaging.images import form_images
from processing.pipeline import noise_band_of, pose_of, resolve_settings, volume_of

from .conftest import SCENES


@pytest.fixture(scope="module")
def pelagic():
    """12 pings of the default scene (noise on, noise from a region, Rayleigh threshold)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = acoustics.load_scene(SCENES / "default.yaml")
    return scene, acoustics.simulate(scene, pings=range(12))


def _all_at_once(tree):
    st = resolve_settings(tree)
    rec = processing.read_record(tree)
    im = form_images(rec, st.image, noise_band_hz=noise_band_of(tree))
    vol = volume_of(tree, st, image_range_m=(im.range_m[0], im.range_m[-1]))
    return detect_all(im, rec, st.detect, vol, upsample=im.interpolation, pose=pose_of(tree)), st, rec, vol


@pytest.mark.parametrize("chunk,workers", [(1, 1), (5, 2), (12, 1), (100, 3)])
def test_chunked_detection_equals_processing_every_ping_at_once(pelagic, chunk, workers):
    """Cutting the record into chunks (and imaging them on threads) changes nothing: the pooled
    noise fit sees exactly the same cells, so thresholds and detections are identical."""
    _, tree = pelagic
    ref, st, rec, vol = _all_at_once(tree)
    det, _ = detect_record(rec, st, vol, noise_band_hz=noise_band_of(tree), pose=pose_of(tree),
                           chunk_pings=chunk, workers=workers)
    assert det.noise.sigma == ref.noise.sigma
    np.testing.assert_array_equal(det.threshold_per_ping, ref.threshold_per_ping)
    assert set(det.table) == set(ref.table)
    for k, v in ref.table.items():
        np.testing.assert_array_equal(det.table[k], v, err_msg=k)


def _two_pass(rec, st, vol, tree, chunk):
    """The chain as it was: a first pass images the noise region's rows of every chunk for the
    pooled fit, a second images every chunk again and detects with it."""
    band, pose = noise_band_of(tree), pose_of(tree)
    sts = [slice(p0, min(p0 + chunk, rec.samples.shape[0]))
           for p0 in range(0, rec.samples.shape[0], chunk)]
    im_st = st.image
    if st.detect.noise.source == "region":
        lo, hi = st.detect.noise.range_m
        im_st = im_st.model_copy(update={"range_m": (max(lo, im_st.range_m[0]),
                                                     min(hi, im_st.range_m[1]))})
    cells = []
    for sl in sts:
        im = form_images(record_pings(rec, sl), im_st, noise_band_hz=band)
        mags = np.abs(im.image[:, im.group_index(st.detect.image_group)])
        cells.append(noise_cells(mags, st.detect, im.range_m, im.beam_angle_rad))
    fit = fit_noise_cells(np.concatenate(cells), st.detect, n_beams=im.beam_angle_rad.size,
                          upsample=st.image.interpolation)
    parts = []
    for sl in sts:
        sub = record_pings(rec, sl)
        im = form_images(sub, st.image, noise_band_hz=band)
        det = detect_all(im, sub, st.detect, vol, upsample=im.interpolation, pose=pose, noise=fit)
        det.table["ping"] = det.table["ping"] + sl.start
        parts.append(det)
    table = {k: np.concatenate([d.table[k] for d in parts]) for k in parts[0].table}
    return table, np.concatenate([d.threshold_per_ping for d in parts]), fit


def _assert_same_detections(table, ref):
    """Same rows, same flags and indices, same numbers to float rounding."""
    assert set(table) == set(ref)
    for k, v in ref.items():
        if np.asarray(v).dtype.kind == "f":
            np.testing.assert_allclose(table[k], v, rtol=1e-12, atol=0, err_msg=k)
        else:
            np.testing.assert_array_equal(table[k], v, err_msg=k)


def _with_detect(st, **update):
    noise = update.pop("noise", {})
    detect = st.detect.model_copy(update={**update,
                                          "noise": st.detect.noise.model_copy(update=noise)})
    return st.model_copy(update={"detect": detect})


def _counting_images(monkeypatch):
    """Count the chunks the chain images."""
    calls = []

    def counted(*args, **kwargs):
        calls.append(args[0].samples.shape[0])
        return form_images(*args, **kwargs)
    monkeypatch.setattr(chain, "form_images", counted)
    return calls


@pytest.mark.filterwarnings("ignore::processing.detection.detect.DetectionWarning")  # fish in the cells
@pytest.mark.parametrize("update", [
    {},                                                       # the default: Rayleigh, region
    {"noise": {"source": "image", "estimator": "median"}},    # a pooled fit of whole images
    {"method": "fixed", "value": 6.0, "value_units": "noise_mean"},
    {"method": "cfar"},                                       # σ only for the SNR
])
def test_one_imaging_pass_detects_what_the_two_pass_chain_detected(pelagic, monkeypatch, update):
    """Each ping is imaged once, and the detections, thresholds and pooled fit are those of the
    chain that imaged every ping twice (noise first, detection second)."""
    _, tree = pelagic
    _, st, rec, vol = _all_at_once(tree)
    st = _with_detect(st, **update)
    ref, ref_thr, ref_fit = _two_pass(rec, st, vol, tree, chunk=5)
    calls = _counting_images(monkeypatch)
    det, _ = detect_record(rec, st, vol, noise_band_hz=noise_band_of(tree), pose=pose_of(tree),
                           chunk_pings=5, workers=2)
    assert calls == [5, 5, 2]
    assert det.noise.sigma == pytest.approx(ref_fit.sigma, rel=1e-12)
    np.testing.assert_allclose(det.threshold_per_ping, ref_thr, rtol=1e-12)
    assert det.table["ping"].size > 0
    _assert_same_detections(det.table, ref)


@pytest.mark.parametrize("update", [
    {"noise": {"per_ping": True}},
    {"method": "cfar", "noise": {"source": "image"}},
    {"method": "fraction_of_peak", "noise": {"source": "image"}},
    {"method": "fixed", "value": 50.0, "value_units": "counts", "noise": {"source": "image"}},
])
def test_settings_without_a_pooled_noise_fit_image_each_ping_once(pelagic, monkeypatch, update):
    _, tree = pelagic
    ref, st, rec, vol = _all_at_once(tree)
    st = _with_detect(st, **update)
    im = form_images(rec, st.image, noise_band_hz=noise_band_of(tree))
    ref = detect_all(im, rec, st.detect, vol, upsample=im.interpolation, pose=pose_of(tree))
    calls = _counting_images(monkeypatch)
    det, _ = detect_record(rec, st, vol, noise_band_hz=noise_band_of(tree), pose=pose_of(tree),
                           chunk_pings=5, workers=2)
    assert calls == [5, 5, 2]
    _assert_same_detections(det.table, ref.table)


@pytest.mark.parametrize("factor", [1.0, 3.0])
def test_a_chunk_whose_candidate_bound_is_too_high_is_imaged_again(pelagic, monkeypatch, factor):
    """The candidates of a chunk are those above a bound of the final threshold; where the
    pooled threshold falls below it (forced here by raising the bound to the chunk's own σ, or
    3 times it) the chunk is imaged and detected again, and nothing changes."""
    _, tree = pelagic
    ref, st, rec, vol = _all_at_once(tree)
    calls = _counting_images(monkeypatch)
    monkeypatch.setattr(chain, "BOUND_SIGMA_FACTOR", factor)
    det, _ = detect_record(rec, st, vol, noise_band_hz=noise_band_of(tree), pose=pose_of(tree),
                           chunk_pings=3, workers=2)
    n_chunks = 4
    if factor == 3.0:   # the bound lies above every chunk's threshold: all imaged twice
        assert len(calls) == 2 * n_chunks
    else:               # some chunk's own σ is at least the pooled one; maybe equal
        assert n_chunks <= len(calls) < 2 * n_chunks
    assert det.noise.sigma == ref.noise.sigma
    np.testing.assert_array_equal(det.threshold_per_ping, ref.threshold_per_ping)
    _assert_same_detections(det.table, ref.table)


@pytest.mark.filterwarnings("ignore::processing.detection.detect.DetectionWarning")  # zeros in the cells
def test_a_noise_free_chunk_is_detected_with_the_pooled_fit(pelagic, monkeypatch):
    """A chunk without noise of its own has no bound for its candidates: it is imaged again
    once the pooled fit is known, and detects what processing every ping at once detects."""
    _, tree = pelagic
    _, st, rec, vol = _all_at_once(tree)
    samples = np.array(np.asarray(rec.samples))
    samples[:3] = 0
    rec = replace(rec, samples=samples)
    im = form_images(rec, st.image, noise_band_hz=noise_band_of(tree))
    ref = detect_all(im, rec, st.detect, vol, upsample=im.interpolation, pose=pose_of(tree))
    calls = _counting_images(monkeypatch)
    det, _ = detect_record(rec, st, vol, noise_band_hz=noise_band_of(tree), pose=pose_of(tree),
                           chunk_pings=3, workers=1)
    assert len(calls) == 5     # the 4 chunks, and the noise-free one again
    assert det.noise.sigma == ref.noise.sigma
    assert not np.isin(det.table["ping"], [0, 1, 2]).any()
    _assert_same_detections(det.table, ref.table)


def test_kept_images_are_those_of_the_chosen_pings(pelagic):
    _, tree = pelagic
    _, st, rec, vol = _all_at_once(tree)
    full = form_images(rec, st.image, noise_band_hz=noise_band_of(tree))
    _, kept = detect_record(rec, st, vol, noise_band_hz=noise_band_of(tree), chunk_pings=5,
                            keep_pings=[7, 0, 11])
    np.testing.assert_array_equal(kept.image, full.image[[7, 0, 11]])


def test_stored_native_images_are_every_interpolated_rows_uth_sample(pelagic):
    """``images="native"`` keeps every U-th row: the images at the data's own sampling."""
    _, tree = pelagic
    full = processing.images_of(processing.image(tree, storage="full"))
    native = processing.images_of(processing.count(tree, images="native"))
    u = full.interpolation
    assert native.interpolation == 1 and u == 4
    np.testing.assert_allclose(native.image, full.image[:, :, ::u], rtol=0,
                               atol=1e-6 * np.abs(full.image).max())  # float32 storage
    np.testing.assert_array_equal(native.range_m, full.range_m[::u])


def test_interferometric_phase_and_elevation_are_derived_not_stored(pelagic):
    _, tree = pelagic
    stored = processing.image(tree)["Processing"].ds
    assert "interferometric_phase" not in stored and "elevation" not in stored
    im = processing.images_of(processing.image(tree))
    i_a, i_b = im.image[:, 0], im.image[:, 1]
    np.testing.assert_array_equal(im.psi_rad, np.angle(i_a * np.conj(i_b)))
    cells = (np.array([0, 3]), np.array([10, 500]), np.array([2, 17]))
    np.testing.assert_array_equal(im.psi_at(*cells), im.psi_rad[cells])


# ------------------------------------------------------------------ geometry cache
def test_geometry_cache_hit_equals_the_computation_and_damage_is_recomputed(tmp_path, monkeypatch):
    from acoustics.sonar import cache
    monkeypatch.setenv("ABACUS_CACHE_DIR", str(tmp_path))
    calls = []

    def compute():
        calls.append(1)
        return (1.25, np.arange(5.0))

    a = cache.per_geometry("probe", (b"geometry", 420e3), compute)
    cache._CACHE.clear()                     # a new process: memory empty, disk warm
    b = cache.per_geometry("probe", (b"geometry", 420e3), compute)
    assert len(calls) == 1 and b[0] == a[0] and np.array_equal(b[1], a[1])
    (entry,) = tmp_path.glob("probe-*.npz")
    entry.write_bytes(b"not an npz")         # a damaged entry is recomputed, never an error
    cache._CACHE.clear()
    c = cache.per_geometry("probe", (b"geometry", 420e3), compute)
    assert len(calls) == 2 and np.array_equal(c[1], a[1])
    monkeypatch.setenv("ABACUS_CACHE_DIR", "off")
    assert cache.cache_dir() is None


def test_cached_beam_table_matches_the_thesis_after_a_round_trip(tmp_path, monkeypatch):
    from acoustics.sonar import cache
    from acoustics.sonar.beam_table import beam_table
    monkeypatch.setenv("ABACUS_CACHE_DIR", str(tmp_path))
    cache._CACHE.clear()
    first = beam_table()
    cache._CACHE.clear()
    again = beam_table()                     # from disk (JSON)
    assert again == first
    tx = again["transmitter"]["abacus"]["normal"]
    assert abs(tx["azimuth_3db_deg"] - 10.28) < 0.05   # thesis Table 3.2


# ------------------------------------------------------------------ the run folder
def _run(*args, cwd):
    code = f"import sys; from abacus.cli import main; sys.exit(main({list(args)!r}))"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd)


def test_run_folder_appears_whole_and_is_never_overwritten_silently(tmp_path):
    r = _run("run", "two_targets", "-o", "out", "--no-plots", "--pings", "2", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir()) == ["beams.json", "counts.json",
                                                      "detections.csv", "run.nc",
                                                      "scene.resolved.yaml"]
    counts = json.loads((out / "counts.json").read_text())
    assert [p["count_after"] for p in counts["pings"]] == [2, 2]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]          # no temporaries left
    again = _run("run", "two_targets", "-o", "out", "--no-plots", cwd=tmp_path)
    assert again.returncode == 2 and "--overwrite" in again.stderr and "Traceback" not in again.stderr
    over = _run("run", "two_targets", "-o", "out", "--pings", "1", "--overwrite", cwd=tmp_path)
    assert over.returncode == 0, over.stderr
    assert (out / "images" / "fan_beam.png").is_file() and (out / "counts" / "counts.png").is_file()
    assert [p["ping_index"] for p in json.loads((out / "counts.json").read_text())["pings"]] == [0]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_default_run_folder_stays_under_runs_whatever_the_scene_name(tmp_path):
    from abacus.runs import default_run_folder
    for name in ("../../x", "/etc/passwd", "..", "a/b\\c", "ok-name_1.2"):
        folder = default_run_folder(name)
        assert folder.parts[0] == "runs" and len(folder.parts) == 2
        assert ".." not in folder.parts and folder.name not in ("", ".", "..")


def test_a_threshold_sweep_scores_each_setting_as_counting_alone_would(pelagic):
    """evaluate() shares one pool of candidate peaks among settings that differ only in their
    threshold; each setting must still get exactly what counting with it alone gives."""
    from abacus.evaluate import evaluate
    _, tree = pelagic
    tree = tree.isel(ping_time=slice(0, 4)) if hasattr(tree, "isel") else tree
    base = resolve_settings(tree)
    sweep = [base] + [base.model_copy(update={"detect": base.detect.model_copy(update={
        "method": "fixed", "value": v})}) for v in (600.0, 900.0, 1500.0)]
    ev = evaluate(tree, sweep)["per_ping"]
    for i, st in enumerate(sweep):
        counts = processing.counts_of(processing.count(tree, st))
        for k in ("count_before", "count_after", "hits_after", "misses_after", "false_alarms_after"):
            np.testing.assert_array_equal(ev[k][i], counts[k].values, err_msg=f"setting {i}: {k}")
