"""Physical fish TS: the swimbladder by physical optics against an independent model (the
prolate spheroidal modal series of ICES echoSMs, values in tests/data/psms_reference.json made by
benchmarks/fish_ts_reference.py), and what a scene of such fish looks like."""
from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

import acoustics
from acoustics.scene import SceneWarning, scene_from_text
from acoustics.scene.targets_spec import SwimbladderTS
from acoustics.targets.fish import body_axis, fish_amplitude, swimbladder_table

from .conftest import ROOT

REF = json.loads((ROOT / "tests" / "data" / "psms_reference.json").read_text())
K = 2 * np.pi * REF["frequency_hz"] / REF["sound_speed_m_s"]


def _bladder(a, b, **kw):
    return SwimbladderTS.model_validate({"model": "swimbladder", "length_m": 2 * a, "width_m": 2 * b,
                                         **kw})


@pytest.mark.parametrize("row", REF["rows"], ids=lambda r: f"a{r['a_m']}-b{r['b_m']}-{r['tilt_deg']}deg")
def test_swimbladder_ts_matches_the_modal_series_within_1_db(row):
    alpha, f = swimbladder_table(_bladder(row["a_m"], row["b_m"]), K)
    ts = 20 * np.log10(np.interp(math.radians(row["tilt_deg"]), alpha, np.abs(f)))
    assert ts == pytest.approx(row["ts_db"], abs=1.0)


def test_broadside_is_the_geometric_optics_limit():
    """At broadside a long spheroid's physical-optics echo tends to geometric optics,
    σ_bs = R1 R2 / 4 = a² / 4 (R1 = b, R2 = a²/b): |f| = a / 2."""
    a, b = 0.05, 0.01
    alpha, f = swimbladder_table(_bladder(a, b), K)
    assert abs(f[np.argmin(np.abs(alpha))]) == pytest.approx(a / 2, rel=0.05)


def test_incidence_angle_of_a_fish_below_the_sonar():
    """A horizontal fish straight below the transmitter is seen broadside (α = 0) whatever its
    heading; tilted by τ it is seen at α = τ (nose up: the echo leaves the broadside lobe)."""
    spec = _bladder(0.03, 0.005)
    f0, a0 = fish_amplitude(spec, [[0, 0, 20.0]] * 3, [0, 0, 0], np.radians([0, 45, 170]),
                            np.zeros(3), K)
    np.testing.assert_allclose(a0, 0.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(f0), np.abs(f0[0]))
    _, a1 = fish_amplitude(spec, [[0, 0, 20.0]], [0, 0, 0], [0.3], [math.radians(8)], K)
    assert math.degrees(abs(a1[0])) == pytest.approx(8.0, abs=1e-9)
    np.testing.assert_allclose(np.linalg.norm(body_axis([0.3, 1.0], [0.1, -0.4]), axis=1), 1.0)


def test_a_school_of_realistic_fish_has_realistic_target_strengths():
    """Bladders of 6 cm x 1 cm tilted N(0, 10°): TS at most the bladder's broadside value (the
    modal series' −36.0 dB at 0.1°, a = 3 cm, b = 5 mm), and most fish between −55 and −35 dB —
    the range of real fish at 420 kHz, not the thesis' −3 dB."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        sc = scene_from_text("name: fish\nmedium: {sound_speed_m_s: 1500}\ntargets:\n  populations:\n"
                             "    - {kind: uniform_cuboid, x_m: [-1,1], y_m: [-2,2], z_m: [15,25], count: 300,\n"
                             "       backscatter: {model: swimbladder, length_m: 0.06, width_m: 0.01}}\n")
    ts = acoustics.simulate(sc, pings=range(2))["Simulation/Ground_truth"].ds["target_ts"].values
    broadside = next(r["ts_db"] for r in REF["rows"]
                     if r["a_m"] == 0.03 and r["b_m"] == 0.005 and r["tilt_deg"] == 0.1)
    assert ts.max() <= broadside + 0.5
    assert np.mean((ts > -55) & (ts < -35)) > 0.85
