"""A school too dense for abacus' single-scattering model is warned of, in one line naming it
(acoustics/scene/checks.py; docs/scenes.md, "Single scattering and dense schools")."""
from __future__ import annotations

import math
import warnings

import pytest

from acoustics.scene import SceneWarning, scene_from_text
from acoustics.scene.checks import SINGLE_SCATTERING_DEPTH, cross_check, school_optical_depth

SCENE = """
name: dense
sonar:
  pose: {{position_m: [0.0, 0.0, 1.0], boresight: [0.0, 0.0, 1.0], receiver_axis: [0.0, 1.0, 0.0]}}
targets:
  populations:
    - kind: school
      center_m: [0.0, 0.0, 19.0]
      semi_axes_m: [1.0, 1.0, 1.5]
      count: {count}
      nearest_neighbour_m: 0.05
      backscatter: {{model: swimbladder, length_m: 0.06, width_m: 0.01}}
      label: herring
pings: {{count: 1}}
"""


def _scene(count):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return scene_from_text(SCENE.format(count=count))


def test_optical_depth_is_density_times_extinction_times_chord():
    """Looking straight down the vertical 1.5 m semi-axis: L = 3 m; a 6 × 1 cm swimbladder has
    σ_e = 2 π a b = 2π · 0.03 · 0.005 m² (twice its broadside shadow); n = count / (4/3 π abc)."""
    sc = _scene(300)
    tau, n, sig, chord = school_optical_depth(sc.targets.populations[0], sc.sonar.pose.position_m)
    assert chord == pytest.approx(3.0, rel=1e-12)
    assert sig == pytest.approx(2 * math.pi * 0.03 * 0.005, rel=1e-12)
    assert n == pytest.approx(300 / (4 / 3 * math.pi * 1.5), rel=1e-12)
    assert tau == pytest.approx(n * sig * chord, rel=1e-12)


def test_a_school_beyond_the_limit_is_warned_of_once_by_name_and_one_below_is_not():
    """τ = 0.1 falls at n = 0.1 / (σ_e L) = 35.4 fish/m³, 222 fish in this 6.28 m³ school."""
    limit = SINGLE_SCATTERING_DEPTH / (2 * math.pi * 0.03 * 0.005 * 3.0) * (4 / 3 * math.pi * 1.5)
    assert 215 < limit < 230
    dense = [m for m, k in cross_check(_scene(int(limit * 1.2))) if "single scattering" in m]
    loose = [m for m, k in cross_check(_scene(int(limit * 0.8))) if "single scattering" in m]
    assert len(dense) == 1 and not loose
    assert "'herring'" in dense[0] and "\n" not in dense[0] and "dB two-way" in dense[0]
    assert [k for m, k in cross_check(_scene(int(limit * 1.2))) if "single scattering" in m] == \
        ["targets.populations[0]"]


def test_scene_check_prints_the_warning(tmp_path):
    from .test_scene import _abacus
    p = tmp_path / "dense.yaml"
    p.write_text(SCENE.format(count=300))
    r = _abacus("scene", "check", str(p))
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in (r.stdout + r.stderr).splitlines() if "single scattering" in ln]
    assert len(lines) == 1 and "herring" in lines[0] and "targets.populations[0]" in lines[0]
