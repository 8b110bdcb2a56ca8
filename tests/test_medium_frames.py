"""Medium (absorption, sound speed) and coordinate frames."""
from __future__ import annotations

import ast
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from acoustics import Medium, Pose, cartesian_to_spherical, francois_garrison_db_per_m, spherical_to_cartesian
from acoustics.medium import mackenzie_sound_speed_m_s

from .conftest import ROOT


def test_mackenzie_check_value():
    """Mackenzie (1981) gives 1550.744 m/s at 25 °C, 35 PSU, 1000 m."""
    assert mackenzie_sound_speed_m_s(25, 35, 1000) == pytest.approx(1550.744, abs=1e-3)


def _ainslie_mccolm_db_per_m(f_hz, t, s, depth_m, ph):
    """Ainslie & McColm (1998), J. Acoust. Soc. Am. 103(3), 1671: a simplified fit to F&G."""
    f, z = f_hz / 1e3, depth_m / 1e3
    f1 = 0.78 * math.sqrt(s / 35) * math.exp(t / 26)
    f2 = 42 * math.exp(t / 17)
    a = (0.106 * f1 * f * f / (f * f + f1 * f1) * math.exp((ph - 8) / 0.56)
         + 0.52 * (1 + t / 43) * (s / 35) * f2 * f * f / (f * f + f2 * f2) * math.exp(-z / 6)
         + 0.00049 * f * f * math.exp(-(t / 27 + z / 17)))
    return a / 1e3


@pytest.mark.parametrize("t", [0.0, 10.0, 20.0, 25.0])
@pytest.mark.parametrize("f", [38e3, 120e3, 420e3])
def test_francois_garrison_agrees_with_ainslie_mccolm(t, f):
    """A&M is an independent fit to the same data; it agrees with F&G to ~10 %."""
    fg = francois_garrison_db_per_m(f, t, 35.0, 20.0, 8.0)
    assert fg == pytest.approx(_ainslie_mccolm_db_per_m(f, t, 35.0, 20.0, 8.0), rel=0.10)


def test_absorption_near_0p1_db_per_m_at_420_khz():
    """At 420 kHz, 10 °C, sea water absorbs about 0.1 dB/m (F&G; Lurton, Fig. 2.7 of the thesis)."""
    assert 0.08 < francois_garrison_db_per_m(420_375, 10, 35, 20, 8) < 0.12


def test_one_way_gain_is_spreading_times_absorption():
    m = Medium(absorption_db_per_m=0.1)
    assert m.one_way_gain(20.0) == pytest.approx(10 ** (-0.1 * 20 / 20) / 20.0, rel=1e-15)
    assert np.isfinite(m.one_way_gain(0.0))  # clamped at 1 mm, never inf


@settings(max_examples=200, deadline=None)
@given(r=st.floats(1e-3, 1e4), th=st.floats(-math.pi + 1e-9, math.pi - 1e-9),
       ph=st.floats(-math.pi / 2, math.pi / 2))
def test_spherical_round_trip(r, th, ph):
    p = spherical_to_cartesian(r, th, ph)
    r2, th2, ph2 = cartesian_to_spherical(p)
    assert r2 == pytest.approx(r, rel=1e-12)
    assert ph2 == pytest.approx(ph, abs=1e-9)
    if abs(math.cos(ph)) > 1e-6:  # azimuth is undefined on the ±y axis
        assert math.cos(th2 - th) == pytest.approx(1.0, abs=1e-9)


def test_thesis_frame_signs():
    """θ from +z towards +x, φ from the x–z plane towards +y (thesis §2.1.1)."""
    assert np.allclose(spherical_to_cartesian(1, math.radians(90), 0), [1, 0, 0], atol=1e-15)
    assert np.allclose(spherical_to_cartesian(1, 0, math.radians(90)), [0, 1, 0], atol=1e-15)
    r, th, ph = cartesian_to_spherical(np.zeros(3))
    assert (r, th, ph) == (0.0, 0.0, 0.0)


def test_pose_round_trip_and_default_down_looking():
    pose = Pose.from_axes([1.0, 2.0, 3.0], [0, 0, 1], [0, 1, 0])
    assert np.allclose(pose.to_world([0, 0, 10.0]), [1, 2, 13])   # boresight is down
    assert np.allclose(pose.to_world([1.0, 0, 0]), [1, 3, 3])      # +x_s is starboard
    assert np.allclose(pose.to_world([0, 1.0, 0]), [0, 2, 3])      # +y_s is aft (right-handed)
    p = np.random.default_rng(1).normal(size=(10, 3))
    assert np.allclose(pose.to_sonar(pose.to_world(p)), p)
    with pytest.raises(ValueError, match="perpendicular"):
        Pose.from_axes([0, 0, 0], [0, 0, 1], [0, 1, 1])


def test_processing_never_imports_acoustics():
    """processing/ must run on recorded data: no import of acoustics anywhere in it."""
    for path in (ROOT / "processing").rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            assert not any(n == "acoustics" or n.startswith("acoustics.") for n in names), path
