"""Values the scene check must refuse before a run meets them (issue 27, classes 4 and 5).

Class 4: values the schema accepted but a run could not use — an image range outside the record,
sizes of 1e300 and resolutions of 1e-300 that overflowed, a floor's correlation length the grid
cannot hold, a Rayleigh law truncated where it has no mass. Class 5: geometry out of the water
under a moving sea — a sonar or target above the surface at some ping (the sea's own height at
each ping time, the platform's pose per ping), a still level below the sonar, waves of 1e6 m or
1e-300 m, a breaking wave, a sea floor above the target.

Each case: ``abacus scene check`` ends with exit status 2 and one line naming the file, line and
key, with no traceback and no numpy RuntimeWarning (the commands run with RuntimeWarnings as
errors); ``abacus simulate`` refuses the same way. The controls (every shipped scene, seas that
stay above everything) pass.
"""
from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

from abacus.runfile import load_run
from acoustics.scene import SceneError, SceneWarning

from .conftest import SCENES

BASE = "name: bounds\nmedium: {sound_speed_m_s: 1500.0}\n"
#: the scenes hold no noise: detect at a fraction of each ping's peak (unless a case says)
DETECT = "processing: {detect: {method: fraction_of_peak, fraction: 0.2}}\n"
POINT = "targets: {points: [{range_m: 15, azimuth_deg: 0, elevation_deg: 0}]}\n"
LOOK = "sonar: {pose: {position_m: [0, 0, 5], boresight: [1, 0, 0], receiver_axis: [0, 1, 0]}}\n"


def _swell(wave="amplitude_m: 0.5, wavelength_m: 25", extra="", target="[15, 0, 3]",
           sonar=LOOK, pings="pings: {count: 16, interval_s: 0.25}\n"):
    return (sonar + f"targets: {{points: [{{frame: world, position_m: {target}}}]}}\n"
            f"boundaries: [{{name: sea, role: surface, mesh: {{shape: swell, center_m: [10, 0], "
            f"size_m: [30, 10], resolution_m: 0.5, waves: [{{{wave}}}]{extra}}}}}]\n"
            "effects: {max_bounces: 1}\n" + pings)


def _floor(mesh):
    return POINT + f"boundaries: [{{name: floor, role: floor, mesh: {mesh}}}]\n"


def _target_mesh(mesh):
    return f"targets: {{meshes: [{{name: m, frame: sonar, mesh: {mesh}}}]}}\n"


def _explicit(tx_line):
    return ("sonar: {preset: null, mode: normal, transmitter: {line: {" + tx_line + "}}, receiver: "
            "{A: {line: {count: 4, pitch_m: 0.01, axis: x, width_m: 0.01, height_m: 0.01}}}}\n" + POINT)


# name: (scene body, key the one line names, words it must hold)
REFUSED = {
    # class 4: the record, overflows, resolutions
    "image range beyond the record": ("sampling: {samples: 600}\n"
                                      "processing: {image: {range_m: [18, 21]}, detect: "
                                      "{method: fraction_of_peak, fraction: 0.2}}\n",
                                      "processing.image.range_m", ("outside the record", "sampling.samples")),
    "image range before the record": ("sampling: {time_offset_s: 0.05}\n"
                                      "processing: {image: {range_m: [5, 10]}, detect: "
                                      "{method: fraction_of_peak, fraction: 0.2}}\n",
                                      "processing.image.range_m", ("outside the record", "time_offset_s")),
    "noise region outside the image": (POINT + "noise: {enabled: true}\nprocessing: {image: {range_m: "
                                       "[10, 20]}, detect: {method: rayleigh, noise: {source: region, "
                                       "range_m: [40, 50]}}}\n",
                                       "processing.detect.noise.range_m", ("no image cell",)),
    "plane size 1e300": (_floor("{shape: plane, center_m: [0, 0, 30], size_m: [100, 1.0e+300]}"),
                         "boundaries[0].mesh.size_m[1]", ("<= 100000",)),
    "rough floor resolution 1e-300": (_floor("{shape: rough_floor, resolution_m: 1.0e-300}"),
                                      "boundaries[0].mesh.resolution_m", (">= 0.001",)),
    "rough floor correlation 1e300": (_floor("{shape: rough_floor, correlation_length_m: 1.0e+300}"),
                                      "boundaries[0].mesh.correlation_length_m", ("<= 100000",)),
    "rough floor correlation beyond its grid": (_floor("{shape: rough_floor, size_m: [20, 20], "
                                                       "correlation_length_m: 50}"),
                                                "boundaries[0].mesh", ("half the floor's smaller side",)),
    "rough floor rms 1e300": (_floor("{shape: rough_floor, rms_height_m: 1.0e+300}"),
                              "boundaries[0].mesh.rms_height_m", ("<= 100",)),
    "height grid spacing 1e300": (_floor("{shape: height_grid, file: g.csv, spacing_m: [1.0e+300, 1]}"),
                                  "boundaries[0].mesh.spacing_m[0]", ("<= 1000",)),
    "sphere radius 1e300": (_target_mesh("{shape: sphere, center_m: [0, 0, 15], radius_m: 1.0e+300}"),
                            "targets.meshes[0].mesh.radius_m", ("<= 100000",)),
    "sphere radius 1e-300": (_target_mesh("{shape: sphere, center_m: [0, 0, 15], radius_m: 1.0e-300}"),
                             "targets.meshes[0].mesh.radius_m", (">= 0.0001",)),
    "mesh scale 1e300": (_target_mesh("{shape: sphere, center_m: [0, 0, 15], radius_m: 0.05, "
                                      "transform: {scale: 1.0e+300}}"),
                         "targets.meshes[0].mesh.transform.scale", ("<= 1000",)),
    "mesh translation 1e300": (_target_mesh("{shape: sphere, radius_m: 0.05, transform: "
                                            "{translate_m: [1.0e+300, 0, 0]}}"),
                               "targets.meshes[0].mesh.transform.translate_m[0]", ("<= 100000",)),
    "target range 1e300": ("targets: {points: [{range_m: 1.0e+300, azimuth_deg: 0, elevation_deg: 0}]}\n",
                           "targets.points[0].range_m", ("<= 100000",)),
    "target velocity 1e300": ("targets: {points: [{frame: world, position_m: [0, 0, 15], "
                              "velocity_m_s: [1.0e+300, 0, 0]}]}\npings: {count: 2}\n",
                              "targets.points[0].velocity_m_s[0]", ("<= 100",)),
    "sonar position 1e300": ("sonar: {pose: {position_m: [1.0e+300, 0, 5]}}\n" + POINT,
                             "sonar.pose.position_m[0]", ("<= 100000",)),
    "element pitch 1e300": (_explicit("count: 4, pitch_m: 1.0e+300, axis: y, width_m: 0.01, height_m: 0.01"),
                            "sonar.transmitter.line.pitch_m", ("<= 10",)),
    "element width 1e-300": (_explicit("count: 4, pitch_m: 0.01, axis: y, width_m: 1.0e-300, height_m: 0.01"),
                             "sonar.transmitter.line.width_m", (">= 1e-05",)),
    "baseline 1e300": ("sonar: {preset_geometry: {baseline_m: 1.0e+300}}\n" + POINT,
                       "sonar.preset_geometry.baseline_m", ("<= 10",)),
    "sector range 1e300": ("targets: {populations: [{kind: uniform_sector, count: 3, "
                           "range_m: [10, 1.0e+300], "
                           "azimuth_deg: [-5, 5], elevation_deg: [-1, 1]}]}\n",
                           "targets.populations[0].range_m[1]", ("<= 100000",)),
    "school semi-axes 1e-300": ("targets: {populations: [{kind: school, count: 3, center_m: [0, 0, 20], "
                                "semi_axes_m: [1.0e-300, 1, 1]}]}\n",
                                "targets.populations[0].semi_axes_m[0]", (">= 0.0001",)),
    "Rayleigh scale 1e-300": ("targets: {points: [{range_m: 15, azimuth_deg: 0, elevation_deg: 0, "
                              "backscatter: "
                              "{model: rayleigh, scale_m: 1.0e-300, lo_m: 0, hi_m: 1}}]}\n",
                              "targets.points[0].backscatter.scale_m", (">= 1e-06",)),
    "Rayleigh truncated where it has no mass": (
        "targets: {points: [{range_m: 15, azimuth_deg: 0, elevation_deg: 0, backscatter: "
        "{model: rayleigh, scale_m: 0.01, lo_m: 0.5, hi_m: 1}}]}\n",
        "targets.points[0].backscatter", ("6 x scale_m",)),
    "reverberation range 1e300": (_floor("{shape: plane, center_m: [0, 0, 30]}")
                                  + "effects: {reverberation: {enabled: true, max_range_m: 1.0e+300}}\n",
                                  "effects.reverberation.max_range_m", ("<= 100000",)),
    "floor density 1e-300": (_floor("{shape: plane, center_m: [0, 0, 30]}").replace(
        "mesh:", "reflection: {model: rayleigh, density_kg_m3: 1.0e-300}, mesh:")
        + "effects: {max_bounces: 1}\n", "boundaries[0].reflection.rayleigh.density_kg_m3", (">= 1",)),
    "sampling rate 1e-300": ("sampling: {rate_hz: 1.0e-300}\nsignal: {bandwidth_hz: 0}\n" + POINT,
                             "sampling.rate_hz", (">= 100",)),
    "Doppler bin 1e-300": ("effects: {doppler: true, doppler_bin_hz: 1.0e-300}\n" + POINT,
                           "effects.doppler_bin_hz", (">= 0.01",)),
    "swell resolution 1e-300": (_swell(extra=", resolution_m: 1.0e-300").replace("resolution_m: 0.5, ", ""),
                                "boundaries[0].mesh.resolution_m", (">= 0.01",)),
    "swell size 1e300": (_swell().replace("size_m: [30, 10]", "size_m: [1.0e+300, 10]"),
                         "boundaries[0].mesh.size_m[0]", ("<= 100000",)),
    "swell time 1e300": (_swell(extra=", time_offset_s: 1.0e+300"),
                         "boundaries[0].mesh.time_offset_s", ("<= 1000000000",)),
    "swell water depth 1e-300": (_swell(extra=", water_depth_m: 1.0e-300"),
                                 "boundaries[0].mesh.water_depth_m", (">= 0.1",)),
    "wind sea spreading 1e300": (_swell().replace("shape: swell", "shape: wind_sea, spreading: 1.0e+300")
                                 .replace(", waves: [{amplitude_m: 0.5, wavelength_m: 25}]", ""),
                                 "boundaries[0].mesh.spreading", ("<= 1000",)),
    "wind sea fetch 1e-300": (_swell().replace("shape: swell", "shape: wind_sea, fetch_km: 1.0e-300")
                              .replace(", waves: [{amplitude_m: 0.5, wavelength_m: 25}]", ""),
                              "boundaries[0].mesh.fetch_km", (">= 0.01",)),
    # class 5: out of the water
    "swell amplitude 1e6 m": (_swell("amplitude_m: 1000000.0, wavelength_m: 25"),
                              "boundaries[0].mesh.waves[0].amplitude_m", ("<= 30",)),
    "swell wavelength 1e-300 m": (_swell("amplitude_m: 0.5, wavelength_m: 1.0e-300"),
                                  "boundaries[0].mesh.waves[0].wavelength_m", (">= 0.02",)),
    "a breaking swell": (_swell("amplitude_m: 2.0, wavelength_m: 25"), "boundaries[0].mesh.waves[0]",
                         ("waves break", "wavelength_m/14")),
    "swell mesh scale 1e300": (_swell(extra=", transform: {scale: 1.0e+300}"),
                               "boundaries[0].mesh.transform.scale", ("<= 1000",)),
    "still level below the sonar": (_swell(extra=", mean_level_m: 6", target="[15, 0, 8]"),
                                    "boundaries[0].mesh.mean_level_m",
                                    ("in the air", "less than the sonar's z, 5 m")),
    # the target is under the water at ping 0 (a crest over it), in the air half a period later
    "a target under a crest, above the trough": (_swell(target="[25, 0, 0.3]"), "targets.points[0]",
                                                 ("above the surface", "at ping 8")),
    "the sonar above the still surface": (_swell(sonar=LOOK.replace("[0, 0, 5]", "[0, 0, -1]")),
                                          "sonar.pose.position_m", ("1 m above the still surface",
                                                                    "below z = 0.5 m")),
    "the sonar above a trough": (_swell(sonar=LOOK.replace("[0, 0, 5]", "[0, 0, 0.3]")),
                                 "sonar.pose.position_m", ("the sonar", "above the surface", "at ping 8")),
    "a heaving sonar under a swell": (
        # still, 0.6 m down is below every trough (0.5 m); heaved 0.3 m up at t = 2 s, under the
        # trough of that moment, it is not
        _swell(sonar=LOOK.replace("}}", "}, motion: {kind: swell, swell: {heave_amplitude_m: 0.3, "
                                        "heave_period_s: 8.0}}}").replace("[0, 0, 5]", "[0, 0, 0.6]")),
        "sonar.motion", ("moved by the platform", "above the surface", "at ping 8")),
    "a target rising into the air": (
        _swell(target="[15, 0, 1.5]").replace("position_m: [15, 0, 1.5]}",
                                              "position_m: [15, 0, 1.5], velocity_m_s: [0, 0, -0.4]}"),
        "targets.points[0].velocity_m_s", ("above the surface",)),
    "a school reaching above the sea": (
        LOOK + "targets: {populations: [{kind: school, count: 5, center_m: [15, 0, 1.0], "
               "semi_axes_m: [3, 2, 0.8]}]}\nboundaries: [{name: sea, role: surface, mesh: "
               "{shape: swell, center_m: [10, 0], size_m: [30, 10], resolution_m: 0.5, "
               "waves: [{amplitude_m: 0.5, wavelength_m: 25}]}}]\npings: {count: 16, interval_s: 0.25}\n",
        "targets.populations[0]", ("region", "above the surface")),
    "a target below the sea's floor": (_swell(extra=", water_depth_m: 3.0", target="[15, 0, 4.5]",
                                              sonar=LOOK.replace("[0, 0, 5]", "[0, 0, 2]")),
                                       "targets.points[0]",
                                       ("below the sea floor", "water_depth_m")),
    # the run's pings are 104 and 105 (t = 26 s: a trough over the target); pings 0 and 1 find
    # a crest there (accepted below)
    "exposed only in the run's own pings": (
        _swell(target="[25, 0, 0.3]", pings="pings: {count: 2, first: 104, interval_s: 0.25}\n"),
        "targets.points[0]", ("at ping 104 (t = 26 s)",)),
}

ACCEPTED = {
    "a target deep under a swell": _swell(),
    # the wave's period is 4.0 s: a ping every period finds its crest over the target, which
    # stands above the still level but in the water at every ping
    "a target that every ping finds under a crest": _swell(
        target="[25, 0, -0.2]", pings="pings: {count: 4, interval_s: 4.00226}\n"),
    "the same target at pings 0 and 1": _swell(target="[25, 0, 0.3]",
                                              pings="pings: {count: 2, interval_s: 0.25}\n"),
    "a heaving sonar deep enough": _swell(sonar=LOOK.replace(
        "}}", "}, motion: {kind: swell, swell: {heave_amplitude_m: 0.3, heave_period_s: 8.0}}}")
        .replace("[0, 0, 5]", "[0, 0, 0.85]")),
    "a wind sea over a school": (LOOK.replace("[0, 0, 5]", "[0, 0, 6]")
                                 + "targets: {populations: [{kind: school, count: 5, center_m: [15, 0, 5], "
                                 "semi_axes_m: [3, 2, 1]}]}\nboundaries: [{name: sea, role: surface, "
                                 "mesh: {shape: wind_sea, wind_speed_m_s: 8, center_m: [10, 0], "
                                 "size_m: [30, 20], resolution_m: 0.5}}]\n"
                                 "pings: {count: 20, interval_s: 0.5}\n"),
}

_DRIVER = """
import contextlib, io, json, os, sys, warnings
warnings.simplefilter("error", RuntimeWarning)
from abacus.cli import main
out = {}
for folder in sys.argv[2:]:
    os.chdir(folder)
    err, std = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
        code = main([*sys.argv[1].split(), "s.yaml"])
    out[folder] = [code, std.getvalue(), err.getvalue()]
print(json.dumps(out))
"""


def _cli(command, folders):
    """Run ``abacus <command> s.yaml`` in each folder, in one interpreter whose RuntimeWarnings
    are errors: {folder: (exit status, stdout, stderr)}."""
    r = subprocess.run([sys.executable, "-W", "error::RuntimeWarning", "-c", _DRIVER, command,
                        *map(str, folders)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def _scene(body):
    return BASE + body + ("" if "processing:" in body else DETECT)


def _write(root, cases):
    folders = {}
    for i, (name, body) in enumerate(cases.items()):
        folder = root / f"case{i:02d}"
        folder.mkdir()
        (folder / "s.yaml").write_text(_scene(body))
        (folder / "g.csv").write_text("30,30,30\n30,30,30\n30,30,30\n")
        folders[name] = folder
    return folders


def _one_line_refusal(name, result, key, words):
    code, out, err = result
    lines = err.strip().splitlines()
    assert code == 2, f"{name}: exit {code}: {err[-500:]}"
    assert "Traceback" not in err and "RuntimeWarning" not in err and "internal error" not in err, name
    errors = [ln for ln in lines if ln.startswith("error:")]
    assert len(errors) == 1 and len(lines) == 1, f"{name}: {err}"
    assert errors[0].startswith("error: s.yaml:") and f": {key}: " in errors[0], f"{name}: {errors[0]}"
    for w in words:
        assert w in errors[0], f"{name}: {w!r} not in {errors[0]}"
    return errors[0]


def test_scene_check_refuses_each_value_in_one_line(tmp_path):
    folders = _write(tmp_path, {n: body for n, (body, _, _) in REFUSED.items()})
    results = _cli("scene check", list(folders.values()))
    for name, (_, key, words) in REFUSED.items():
        _one_line_refusal(name, results[str(folders[name])], key, words)


def test_simulate_refuses_the_same_way(tmp_path):
    chosen = ["image range beyond the record", "plane size 1e300", "sphere radius 1e-300",
              "swell wavelength 1e-300 m", "a target under a crest, above the trough",
              "a heaving sonar under a swell"]
    folders = _write(tmp_path, {n: REFUSED[n][0] for n in chosen})
    checked = _cli("scene check", list(folders.values()))
    simulated = _cli("simulate -o out.nc", list(folders.values()))
    for name in chosen:
        _, key, words = REFUSED[name]
        line = _one_line_refusal(name, simulated[str(folders[name])], key, words)
        assert line == checked[str(folders[name])][2].strip()
        assert not (folders[name] / "out.nc").exists()


def test_seas_that_keep_everything_wet_pass(tmp_path):
    folders = _write(tmp_path, ACCEPTED)
    results = _cli("scene check", list(folders.values()))
    for name, folder in folders.items():
        code, out, err = results[str(folder)]
        assert code == 0 and "ok" in out, f"{name}: {err}"
        assert "Traceback" not in err and "RuntimeWarning" not in err
        # legal but surprising: said, once, as a warning naming the target
        crest = "a target that every ping finds under a crest"
        said = [ln for ln in err.splitlines() if "every ping of the run finds a crest" in ln]
        assert len(said) == (1 if name == crest else 0), f"{name}: {err}"
        if said:
            assert said[0].startswith("warning: s.yaml:") and ": targets.points[0]: " in said[0]


def test_every_shipped_scene_still_passes():
    for path in sorted(SCENES.glob("*.yaml")):
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            warnings.simplefilter("ignore", SceneWarning)
            scene = load_run(path)
        assert scene.physics_notes == ()


def test_shipped_sea_scenes_pass_the_command_line_check(tmp_path):
    folders = {}
    for name in ("swell_ghost", "pelagic_wind_sea", "rolling_swell"):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "s.yaml").write_text((SCENES / f"{name}.yaml").read_text())
        folders[name] = folder
    results = _cli("scene check", list(folders.values()))
    for name, folder in folders.items():
        code, out, err = results[str(folder)]
        assert code == 0 and "ok" in out, f"{name}: {err}"


def test_a_run_too_long_for_the_sea_check_is_said_not_refused(tmp_path):
    """A wind sea of 60 x 60 m at 0.25 m (22 000 wave components) over 5000 pings: the per-ping
    check takes its budget's worth of pings, and the scene loads with a warning naming the sea
    and the pings checked."""
    p = tmp_path / "long.yaml"
    p.write_text(BASE + DETECT + LOOK.replace("[0, 0, 5]", "[0, 0, 3]")
                 + "targets: {points: [{frame: world, position_m: [15, 0, 2.5]}]}\n"
                 "boundaries: [{name: sea, role: surface, mesh: {shape: wind_sea, wind_speed_m_s: 10, "
                 "size_m: [60, 60], resolution_m: 0.25}}]\npings: {count: 5000, interval_s: 0.5}\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_run(p)
    said = [str(w.message) for w in caught if issubclass(w.category, SceneWarning)]
    assert any("boundaries[0].mesh" in m and "checked" in m and "of 0–4999" in m for m in said), said
    assert len(scene.physics_notes) == 1


def test_sea_series_match_the_surface_pointwise():
    """The scene check's two ways to evaluate the sea (fixed points over many pings, moving
    points one by one) are the surface's own elevation."""
    from acoustics.paths.sea_surface import swell, wind_sea
    rng = np.random.default_rng(7)
    for surf in (wind_sea(wind_speed_m_s=8.0, size_m=(20.0, 10.0), resolution_m=0.5, seed=3),
                 swell(components=[(0.4, 20.0, 10.0, 30.0), (0.2, 7.0, -40.0, 0.0)])):
        x, y = rng.uniform(-10, 10, 5), rng.uniform(-5, 5, 5)
        t = np.arange(7) * 0.37 + 2.0
        series = surf.elevation_series(x, y, t)
        each = surf.elevation_at(x[:, None], y[:, None], t[None, :])
        ref = np.array([[surf.elevation(x[i], y[i], tk)[0] for tk in t] for i in range(5)])
        np.testing.assert_allclose(series, ref, atol=1e-12)
        np.testing.assert_allclose(each, ref, atol=1e-12)
        assert np.abs(ref).max() <= surf.reach_m


def test_in_process_loading_refuses_what_the_command_refuses(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text(_scene(REFUSED["the sonar above a trough"][0]))
    with pytest.raises(SceneError, match=r"s\.yaml:\d+: sonar\.pose\.position_m: .*at ping 8"):
        load_run(p)
    p.write_text(_scene(REFUSED["image range beyond the record"][0]))
    with pytest.raises(SceneError, match=r"processing\.image\.range_m: the image range 18–21 m lies "
                                         r"outside the record"):
        load_run(p)


def test_the_checked_sea_is_the_simulated_sea():
    """The scene check builds its sea without the mesh module (which imports the scene package):
    the same components as the simulation's, for a wind sea and a swell."""
    from acoustics.paths.meshes import moving_surface
    from acoustics.paths.sea_surface import surface_of
    from acoustics.scene import scene_from_text
    for mesh in ("{shape: wind_sea, wind_speed_m_s: 9, fetch_km: 30, direction_deg: 20, seed: 4, "
                 "size_m: [30, 20], resolution_m: 0.5, water_depth_m: 15, mean_level_m: -0.5}",
                 "{shape: swell, waves: [{amplitude_m: 0.4, wavelength_m: 20, direction_deg: 10, "
                 "phase_deg: 30}, {amplitude_m: 0.1, wavelength_m: 6}]}"):
        scene = scene_from_text(f"name: s\nseed: 11\nsonar: {{pose: {{position_m: [0, 0, 6]}}}}\n"
                                f"boundaries: [{{name: sea, role: surface, mesh: {mesh}}}]\n")
        spec = scene.boundaries[0].mesh
        a, b = surface_of(spec, scene.seed), moving_surface(spec, scene.seed)
        for field in ("x_m", "y_m", "k_m", "amplitude_m", "phase_rad", "omega_rad_s"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
        assert a.mean_level_m == b.mean_level_m

