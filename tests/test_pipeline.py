"""The processing chain over a record a few pings at a time, the geometry caches and the run
folder: same numbers however the work is cut, nothing half-written."""
from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

import acoustics
import processing
from acoustics.scene import SceneWarning
from processing.chain import detect_record
from processing.detection import detect_all
from processing.imaging import form_images
from processing.products import noise_band_of, pose_of, resolve_settings, volume_of

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
    code = f"import sys; from acoustics.cli import main; sys.exit(main({list(args)!r}))"
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
    from acoustics.cli.run import default_run_folder
    for name in ("../../x", "/etc/passwd", "..", "a/b\\c", "ok-name_1.2"):
        folder = default_run_folder(name)
        assert folder.parts[0] == "runs" and len(folder.parts) == 2
        assert ".." not in folder.parts and folder.name not in ("", ".", "..")


def test_a_threshold_sweep_scores_each_setting_as_counting_alone_would(pelagic):
    """evaluate() shares one pool of candidate peaks among settings that differ only in their
    threshold; each setting must still get exactly what counting with it alone gives."""
    from processing.evaluate import evaluate
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
