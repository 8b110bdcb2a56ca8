"""Scene files: loading, resolution, schema, and one clear message per bad input."""
from __future__ import annotations

import math
import subprocess
import sys
import warnings

import pytest

from acoustics import SceneError, SceneWarning, load_scene
from abacus.runfile import json_schema_text
from acoustics.scene import scene_from_text

from .conftest import ROOT, SCENES

EXPLICIT = """
name: explicit
sonar:
  preset: null
  mode: normal
  transmitter:
    line: {count: 4, pitch_m: 0.012, axis: y, width_m: 0.02, height_m: 0.012}
  receiver:
    A:
      elements:
        - {center_m: [-0.0225, 0, 0], width_m: 0.012, height_m: 0.02}
        - {center_m: [-0.0075, 0, 0], width_m: 0.012, height_m: 0.02}
        - {center_m: [0.0075, 0, 0], width_m: 0.012, height_m: 0.02}
        - {center_m: [0.0225, 0, 0], width_m: {width}, height_m: 0.02}
"""


def all_scene_files():
    return sorted(p for p in SCENES.glob("*.yaml"))


@pytest.mark.parametrize("path", all_scene_files(), ids=lambda p: p.name)
def test_every_committed_scene_loads_and_round_trips(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = load_scene(path)
        again = scene_from_text(scene.resolved_text())
    assert again.sha256() == scene.sha256()
    assert again.model_dump() == scene.model_dump()


def test_default_scene_is_the_pelagic_survey():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        s = load_scene(SCENES / "default.yaml")
    pop = s.targets.populations[0]
    assert pop.count == 100 and pop.volume_m3 == pytest.approx(215.6, rel=1e-3)
    # the thesis' noise σ = 126.68 and Rayleigh ρ scale 0.5 m, both x 0.025: its SNR, a fish's TS
    assert s.noise.enabled and s.noise.sigma_counts == pytest.approx(126.68 * 0.025, rel=1e-12)
    bs = pop.backscatter
    assert (bs.scale_m, bs.lo_m, bs.hi_m) == pytest.approx((0.5 * 0.025, 0.25 * 0.025, 1.25 * 0.025))
    assert s.sampling.adc.scale_counts == 16384
    assert s.pings.count == 100


def test_degrees_only_under_deg_keys_and_radians_inside(write_scene):
    p = write_scene("name: t\ntargets:\n  points:\n    - {range_m: 17, azimuth_deg: 0.7, elevation_deg: -0.2}\n")
    t = load_scene(p, check=False).targets.points[0]
    assert t.azimuth == pytest.approx(math.radians(0.7), abs=1e-15)
    assert t.elevation == pytest.approx(math.radians(-0.2), abs=1e-15)
    assert "azimuth_deg: 0.7" in load_scene(p, check=False).resolved_text().replace("'", "")
    p2 = write_scene("name: t\ntargets:\n  points:\n    - {range_m: 17, azimuth: 0.01, elevation_deg: 0}\n", "r.yaml")
    with pytest.raises(SceneError) as e:
        load_scene(p2)
    msg = str(e.value)
    assert "targets.points[0].azimuth" in msg and "unknown key" in msg and "azimuth_deg" in msg


def test_resolved_scene_fills_every_default(write_scene):
    s = load_scene(write_scene("name: minimal\n"), check=False)
    text = s.resolved_text()
    for key in ("absorption_db_per_m:", "receiver_bandwidth_hz: 22727.5", "preset_geometry:",
                "transmitter_stagger_m: 0.0015", "kernel_length: 8", "bandwidth_hz: 22727.5"):
        assert key in text, key
    # the only nulls left are choices made at run time: explicit arrays (preset used), the
    # reverberation range (end of the record), ray threads (every core) and the platform's
    # motion (none: a still platform), physical levels (none: the thesis' units) and the
    # specular search's fan (none: every facet)
    allowed = ("transmitter: null", "receiver: null", "density_per_m3: null", "max_range_m: null",
               "ray_threads: null", "motion: null", "levels: null", "beam_level_db: null")
    body = text.split("processing:")[0]
    for a in allowed:
        body = body.replace(a, "")
    assert "null" not in body


def test_mackenzie_sound_speed_when_null(write_scene):
    s = load_scene(write_scene("name: t\nmedium: {sound_speed_m_s: null, temperature_c: 25, "
                               "salinity_psu: 35, depth_m: 1000}\n"), check=False)
    assert s.medium.sound_speed_m_s == pytest.approx(1550.744, abs=1e-3)


def test_json_schema_file_is_current():
    committed = (SCENES / "scene.schema.json").read_text()
    assert committed == json_schema_text(), (
        "scenes/scene.schema.json is stale: regenerate with "
        "`abacus scene schema > scenes/scene.schema.json`")


# ------------------------------------------------------------------ bad input
def _error(write_scene, text, name="bad.yaml"):
    p = write_scene(text, name)
    with pytest.raises(SceneError) as e:
        load_scene(p)
    return str(e.value), p


def test_unknown_key_names_path_line_and_accepted_keys(write_scene):
    msg, p = _error(write_scene, "name: t\nsonar:\n  mode: normal\n  modee: normal\n")
    assert f"{p}:4" in msg
    assert "sonar.modee" in msg and "unknown key" in msg
    assert "mode" in msg and "pose" in msg  # the accepted keys are listed


def test_wrong_type(write_scene):
    msg, p = _error(write_scene, "name: t\nseed: abc\n")
    assert f"{p}:2" in msg and "seed" in msg and "whole number" in msg and "'abc'" in msg
    msg, _ = _error(write_scene, "name: t\nsampling: {rate_hz: '45455'}\n", "s.yaml")
    assert "sampling.rate_hz" in msg and "must be a number" in msg


def test_negative_size_in_an_element_list(write_scene):
    msg, p = _error(write_scene, EXPLICIT.replace("{width}", "-0.012"))
    assert "sonar.receiver.A.elements[3].width_m" in msg
    assert "must be > 0" in msg and "-0.012" in msg
    assert f"{p}:" in msg


def test_empty_element_list(write_scene):
    text = EXPLICIT.replace("{width}", "0.012").replace(
        "    line: {count: 4, pitch_m: 0.012, axis: y, width_m: 0.02, height_m: 0.012}",
        "    elements: []")
    msg, _ = _error(write_scene, text)
    assert "sonar.transmitter" in msg and "elements is empty" in msg


def test_unreadable_files(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        load_scene(tmp_path / "missing.yaml")
    with pytest.raises(SceneError, match="is a directory"):
        load_scene(tmp_path)
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfe\x00name")
    with pytest.raises(SceneError, match="not a text file"):
        load_scene(binary)


def test_yaml_syntax_error_has_line_and_column(write_scene):
    msg, p = _error(write_scene, "name: t\nsonar:\n  mode: [normal\n")
    assert "YAML syntax error" in msg and str(p) in msg
    assert f"{p}:" in msg


def test_duplicate_key(write_scene):
    msg, p = _error(write_scene, "name: t\nseed: 1\nseed: 2\n")
    assert f"{p}:3" in msg and "seed" in msg and "duplicate key" in msg and "line 2" in msg


def test_angle_out_of_range(write_scene):
    msg, _ = _error(write_scene, "name: t\ntargets:\n  points:\n    - {range_m: 20, azimuth_deg: 0, elevation_deg: 120}\n")
    assert "targets.points[0].elevation_deg" in msg and "[-90, 90] degrees" in msg and "120" in msg


def test_non_finite_and_boolean_numbers(write_scene):
    msg, _ = _error(write_scene, "name: t\nsignal: {duration_s: .inf}\n")
    assert "signal.duration_s" in msg and "finite" in msg
    msg, _ = _error(write_scene, "name: t\nsignal: {duration_s: true}\n", "b.yaml")
    assert "signal.duration_s" in msg and "must be a number" in msg


def test_pose_axes_must_be_perpendicular(write_scene):
    msg, _ = _error(write_scene, "name: t\nsonar:\n  pose: {boresight: [0, 0, 1], receiver_axis: [0, 1, 1]}\n")
    assert "sonar.pose" in msg and "perpendicular" in msg


def test_missing_name_and_empty_file(write_scene):
    msg, _ = _error(write_scene, "seed: 1\n")
    assert "name" in msg and "required" in msg
    msg, _ = _error(write_scene, "", "empty.yaml")
    assert "empty" in msg


def test_bad_discriminator_lists_choices(write_scene):
    msg, _ = _error(write_scene, "name: t\ntargets:\n  populations:\n    - {kind: sphere, count: 3}\n")
    assert "targets.populations[0]" in msg and "uniform_cuboid" in msg and "uniform_sector" in msg


def test_population_count_or_density(write_scene):
    msg, _ = _error(write_scene, "name: t\ntargets:\n  populations:\n    - {kind: uniform_cuboid, "
                                 "x_m: [0, 1], y_m: [0, 1], z_m: [1, 0], count: 3, density_per_m3: 1}\n")
    assert "targets.populations[0]" in msg


def test_preset_and_explicit_arrays_conflict(write_scene):
    msg, _ = _error(write_scene, "name: t\nsonar:\n  transmitter:\n    line: {count: 2, pitch_m: 0.01, "
                                 "axis: y, width_m: 0.01, height_m: 0.01}\n")
    assert "sonar" in msg and "preset" in msg


def test_several_problems_are_all_reported(write_scene):
    msg, _ = _error(write_scene, "name: t\nseed: -1\nsignal: {bandwidth_hz: -5}\npings: {count: 0}\n")
    assert "3 problems" in msg
    for key in ("seed", "signal.bandwidth_hz", "pings.count"):
        assert key in msg


# --------------------------------------------------------------- cross checks
def _warnings(path, loader=None):
    """The SceneWarnings of loading a scene (by default as the application loads a run file:
    the scene's physics and its processing block)."""
    if loader is None:
        from abacus.runfile import load_run as loader
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        loader(path)
    return [str(x.message) for x in w if issubclass(x.category, SceneWarning)]


def test_warns_on_grating_lobes_sampling_and_blind_zone(write_scene):
    p = write_scene("name: t\nsampling: {rate_hz: 30000}\nmedium: {sound_speed_m_s: 1530}\n"
                    "targets:\n  points:\n    - {range_m: 3, azimuth_deg: 0, elevation_deg: 0}\n")
    w = _warnings(p)
    # the ABACUS preset's grating lobes are its design: a note of `scene check`, not a warning
    # every command repeats
    assert not any("grating lobes" in m for m in w)
    from acoustics.scene import cross_check
    notes = []
    cross_check(load_scene(p, check=False), notes=notes)
    assert any("grating lobes at ±14.04°" in m for m, _ in notes)
    assert any("sampling.rate_hz" in m and "2B" in m for m in w)
    assert any("targets.points[0]" in m and "blind zone" in m for m in w)


_ONE_TARGET = ("name: t\ntargets:\n  points:\n    - {range_m: 19.5, azimuth_deg: 0, elevation_deg: 0}\n")


@pytest.mark.parametrize("extra, warned", [
    ("", True),                                                         # rayleigh, no noise
    ("processing:\n  detect: {method: fixed, value: 3, value_units: noise_mean}\n", True),
    ("noise: {enabled: true}\n", False),
    ("processing:\n  detect: {method: fraction_of_peak, fraction: 0.2}\n", False),
    ("processing:\n  detect: {method: fixed, value: 600}\n", False),   # counts: no noise needed
    ("processing:\n  detect: {method: cfar}\n", False),
])
def test_warns_when_a_noise_derived_threshold_has_no_noise_to_derive_from(write_scene, extra, warned):
    """Without noise the images' 'noise' cells are the targets' sidelobes and the numerical
    floor: a threshold derived from them counts the sidelobes (the warning names the key)."""
    w = _warnings(write_scene(_ONE_TARGET + extra))
    hits = [m for m in w if "processing.detect.method" in m and "no noise" in m]
    assert bool(hits) == warned, w


def test_a_noise_free_point_target_is_counted_once():
    """The point-target scene (one unit target, no noise, thesis Fig. 6.1): its sidelobes are
    ≈ 0.05 of the peak in range and 0.02 in azimuth (thesis §6.1.1), below its threshold of 0.2
    of the peak, so exactly the target is detected — where a Rayleigh fit to the sidelobes
    counted 53."""
    import acoustics
    import processing
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneWarning)
        from abacus.runfile import load_run
        scene = load_run(SCENES / "point_target.yaml")
    summary = processing.count_summary(processing.count(acoustics.simulate(scene)))["summary"]
    assert summary["true_in_volume"]["mean"] == 1.0
    assert summary["count_before"]["mean"] == summary["count_after"]["mean"] == 1.0, summary
    assert summary["total_false_alarms_after"] == 0


def test_no_builtin_scene_warns_of_a_threshold_without_noise():
    for path in sorted(SCENES.glob("*.yaml")):
        hits = [m for m in _warnings(path) if "processing.detect.method" in m]
        assert not hits, (path.name, hits)


def test_warns_on_grating_lobes_of_an_explicit_array(write_scene):
    """A user's own array with a pitch over λ/2 gets the warning (it may not be intended)."""
    w = _warnings(write_scene(EXPLICIT.replace("{width}", "0.012")))
    assert any("grating lobes" in m for m in w)


def test_no_spurious_warnings_for_a_dense_array(write_scene):
    text = EXPLICIT.replace("{width}", "0.0012").replace("0.0225", "0.00225").replace("0.0075", "0.00075")
    text = text.replace("width_m: 0.012,", "width_m: 0.0012,")
    w = _warnings(write_scene(text))
    assert not any("grating" in m for m in w)


# -------------------------------------------------------------------- the CLI
def _abacus(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "abacus.cli", *args], capture_output=True,
                          text=True, cwd=cwd or ROOT)


def test_cli_bad_scene_is_one_message_no_traceback(write_scene):
    p = write_scene("name: t\nsonar: {modee: x}\n")
    r = _abacus("scene", "check", str(p))
    assert r.returncode == 2
    assert r.stderr.startswith("error:") and "sonar.modee" in r.stderr
    assert "Traceback" not in r.stderr


def test_cli_scene_show_round_trips(write_scene, tmp_path):
    r = _abacus("scene", "show", str(SCENES / "default.yaml"))
    assert r.returncode == 0, r.stderr
    shown = tmp_path / "shown.yaml"
    shown.write_text(r.stdout)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        from abacus.runfile import load_run
        assert load_run(shown).sha256() == load_run(SCENES / "default.yaml").sha256()
