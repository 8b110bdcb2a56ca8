"""Compiled maths and echo kernels against numpy; target draws against their distributions."""
from __future__ import annotations

import math
import warnings

import numba as nb
import numpy as np
import pytest
from scipy import stats

from acoustics import SceneWarning
from acoustics.sonar.directivity import array_response, element_directivity
from acoustics.synthesis.arrivals import EchoModel, arrivals
from acoustics.synthesis.kernels import EXP_SMALL_LIMIT, cis_cycles, exp_small, sin_over, sincos, sine
from acoustics.medium import Medium
from acoustics.synthesis.receiver import quantize
from acoustics.scene import scene_from_text
from acoustics.sonar.build import preset_sonar
from acoustics.synthesis.synthesize import fractional_delay_table
from acoustics.simulation.setup import make_setup
from acoustics.targets.draw import draw_targets


@nb.njit
def _eval(xs, which):
    out = np.empty((xs.size, 2))
    for i in range(xs.size):
        if which == 0:
            a, b = sincos(xs[i])
        elif which == 1:
            a, b = cis_cycles(xs[i])
        elif which == 2:
            a, b = sin_over(xs[i]), 0.0
        elif which == 4:
            a, b = sine(xs[i]), 0.0
        else:
            a, b = exp_small(xs[i]), 0.0
        out[i, 0], out[i, 1] = a, b
    return out


def test_sincos_over_its_domain():
    x = np.concatenate([np.random.default_rng(0).uniform(-1000, 1000, 200_000),
                        [0.0, -0.0, np.pi / 4, -np.pi / 4, np.pi / 2, np.pi, 3 * np.pi / 2, 1e-300]])
    out = _eval(x, 0)
    tol = 2e-16 * (4 + np.abs(x))  # rounding of q·π/2 and of π/2 itself grow with x
    assert np.all(np.abs(out[:, 0] - np.sin(x)) <= tol)
    assert np.all(np.abs(out[:, 1] - np.cos(x)) <= tol)


def test_sine_over_its_domain():
    """The piston's sine (reduced by π, one polynomial) is as exact as sincos on |x| <= 1e3,
    including the reduction's seams (odd multiples of π/2) and its zeros (multiples of π)."""
    k = np.arange(-40, 41)
    x = np.concatenate([np.random.default_rng(4).uniform(-1000, 1000, 200_000),
                        np.random.default_rng(5).uniform(-20, 20, 100_000),
                        k * np.pi, (k + 0.5) * np.pi, np.nextafter((k + 0.5) * np.pi, np.inf),
                        [0.0, -0.0, 1e-300, -1e-8]])
    out = _eval(x, 4)[:, 0]
    assert np.all(np.abs(out - np.sin(x)) <= 2e-16 * (4 + np.abs(x)))
    small = np.abs(x) < 1.0  # no reduction: relative accuracy near zero
    assert np.all(np.abs(out[small] - np.sin(x[small])) <= 2.3e-16 * np.abs(np.sin(x[small])))


def test_cis_cycles_for_two_way_paths_of_70_m():
    """cycles = (r1 + r2)/λ reaches 4e4 at 70 m; the result must be as exact as float64 allows."""
    c = np.random.default_rng(1).uniform(0, 4e4, 200_000)
    out = _eval(c, 1)
    frac = c - np.floor(c)  # exact in float64
    assert np.abs(out[:, 0] - np.sin(2 * np.pi * frac)).max() < 2e-15
    assert np.abs(out[:, 1] - np.cos(2 * np.pi * frac)).max() < 2e-15


def test_cis_cycles_for_any_float_including_beyond_2_to_the_50():
    """From |c| = 2^50 on, 4c is an integer and floor(4c + 1/2) rounds an odd one up (the tie
    goes to even): the reduction must still leave |f| <= 1/2, so e^{j2πc} stays exact for every
    float64 c (its fraction, taken exactly by np.round, is a multiple of 1/4 up there)."""
    c = np.concatenate([(2.0 ** k + np.array([0.25, 0.5, 0.75, 1.0, 1.25])) * s
                        for k in (49, 50, 51, 52, 60) for s in (1.0, -1.0)])
    out = _eval(c, 1)
    frac = c - np.round(c)  # exact in float64
    assert np.abs(out[:, 0] - np.sin(2 * np.pi * frac)).max() < 2e-15
    assert np.abs(out[:, 1] - np.cos(2 * np.pi * frac)).max() < 2e-15


@pytest.mark.parametrize("tiny", [1e-170, 1e-310, 1e-318, 2e-322])
def test_piston_sinc_product_for_tiny_and_subnormal_arguments(tiny):
    """sinc(a) sinc(b) is 1 − a²/6 ≈ 1 in float64 for |a| ≲ 1e-8, whatever else: one division
    of the two sines' product by a b must not lose a subnormal a's digits (a b underflows, or
    keeps a few bits) — the pattern towards a direction a hair off an element's axis."""
    from acoustics.synthesis.arrivals import _piston
    r = np.hypot(20.0, 20.0)
    b = 3.0 * 20.0 / r
    side = _piston(tiny, 20.0, 20.0, 1.0 / r, 3.0, 0.0, 0.0, 3.0, False)  # a tiny, b = 2.12
    both = _piston(tiny, tiny, 20.0, 1.0 / 20.0, 3.0, 0.0, 0.0, 3.0, False)  # a, b tiny
    assert abs(side - np.sin(b) / b) <= 1e-15
    assert both == 1.0


def test_sin_over_including_zero():
    a = np.concatenate([np.random.default_rng(2).uniform(-60, 60, 100_000), [0.0, 1e-12, -1e-6, 1e-5]])
    out = _eval(a, 2)[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = np.where(a == 0, 1.0, np.sin(a) / a)
    assert out[a == 0][0] == 1.0
    assert np.abs(out - ref).max() < 1e-15


def test_exp_small_within_its_limit():
    x = np.linspace(-EXP_SMALL_LIMIT, EXP_SMALL_LIMIT, 100_001)
    out = _eval(x, 3)[:, 0]
    assert np.abs(out / np.exp(x) - 1).max() < 1e-15


@pytest.mark.parametrize("fidelity", ["far_field", "huygens"])
def test_compiled_arrivals_equal_the_numpy_model(fidelity):
    """τ and A from the numba kernels against an independent numpy evaluation of eq. 2.16–2.23."""
    son = preset_sonar()
    med = Medium(1530.0, 0.1)
    model = EchoModel(son.transmitter, son.receiver.elements, med, 420_375.0, 16384.0, fidelity, (3, 3))
    rng = np.random.default_rng(3)
    p = np.column_stack([rng.uniform(-3, 3, 200), rng.uniform(-1, 1, 200), rng.uniform(0.5, 68, 200)])
    q = rng.uniform(0.2, 1.3, 200) * np.exp(1j * rng.uniform(-np.pi, np.pi, 200))
    tau, amp = arrivals(model, p, q)
    k = med.wavenumber_rad_m(420_375.0)
    t = son.transmitter.phase_center_m
    rx = son.receiver.elements
    r1 = np.linalg.norm(p - t, axis=1)
    r2 = np.linalg.norm(p[:, None, :] - rx.center_m[None], axis=2)
    e_t = array_response(son.transmitter, p, wavenumber_rad_m=k, fidelity=fidelity, subdivisions=(3, 3))
    d = element_directivity(rx, p, wavenumber_rad_m=k, fidelity=fidelity, subdivisions=(3, 3))
    path = r1[:, None] + r2
    expect = (16384.0 * 16 * q[:, None] * e_t[:, None] * d / (r1[:, None] * r2)
              * 10 ** (-0.1 * path / 20) * np.exp(-2j * np.pi * path / med.wavelength_m(420_375.0)))
    np.testing.assert_allclose(tau, path / 1530.0, rtol=1e-14)
    np.testing.assert_allclose(amp, expect, rtol=1e-10, atol=1e-12 * np.abs(expect).max())


def test_fractional_delay_table_is_exact_at_integer_delays():
    for taps in (4, 8, 16, 32):
        t = fractional_delay_table(taps, 0.55)
        e = np.zeros(taps)
        e[taps // 2 - 1] = 1.0
        np.testing.assert_allclose(t[0], e, atol=1e-15)
        # and the kernel of a half-sample delay is symmetric
        mid = t[t.shape[0] // 2]
        np.testing.assert_allclose(mid, mid[::-1], atol=1e-15)
    with pytest.raises(ValueError, match="even"):
        fractional_delay_table(7, 0.5)


def test_quantize_rounds_and_counts_clips():
    x = np.array([[0.4 + 0.6j, 2047.4 - 2048.4j, 3000 + 0j, -5000 + 10j]])
    q, clipped = quantize(x, 12)
    assert q[0, 0] == 0 + 1j and q[0, 1] == 2047 - 2048j
    assert q[0, 2] == 2047 and q[0, 3] == -2048 + 10j
    assert clipped[0] == 2


def _scene(text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return scene_from_text(text)


def test_bounded_rayleigh_matches_the_truncated_law():
    s = _scene("name: r\ntargets:\n  populations:\n    - {kind: uniform_cuboid, frame: sonar, x_m: [-1, 1], "
               "y_m: [-1, 1], z_m: [10, 20], count: 4000, backscatter: {model: rayleigh, scale_m: 0.5, "
               "lo_m: 0.25, hi_m: 1.25}}\n")
    son = preset_sonar()
    rho = draw_targets(make_setup(s).targets, 0, son.pose).rho_m
    assert rho.min() >= 0.25 and rho.max() <= 1.25
    # scipy has no truncated Rayleigh: its CDF built from the Rayleigh's
    f = stats.rayleigh(scale=0.5).cdf
    cdf = lambda x: (f(x) - f(0.25)) / (f(1.25) - f(0.25))  # noqa: E731
    assert stats.kstest(rho, cdf).pvalue > 0.01


def test_sector_population_is_uniform_in_volume():
    s = _scene("name: s\ntargets:\n  populations:\n    - {kind: uniform_sector, range_m: [10, 30], "
               "azimuth_deg: [-5, 5], elevation_deg: [-1, 1], count: 5000}\n")
    t = draw_targets(make_setup(s).targets, 3, preset_sonar().pose)
    r = np.linalg.norm(t.position_sonar_m, axis=1)
    # uniform in volume: r³ is uniform on [10³, 30³]
    assert stats.kstest((r**3 - 1e3) / (2.7e4 - 1e3), "uniform").pvalue > 0.01
    el = np.arcsin(t.position_sonar_m[:, 1] / r)
    assert stats.kstest((np.sin(el) - math.sin(math.radians(-1))) / (2 * math.sin(math.radians(1))),
                        "uniform").pvalue > 0.01


def test_density_gives_poisson_counts_and_fixed_populations_stay_put():
    s = _scene("name: d\ntargets:\n  populations:\n    - {kind: uniform_cuboid, x_m: [0, 2], y_m: [0, 2], "
               "z_m: [10, 15], density_per_m3: 0.5}\n    - {kind: uniform_cuboid, x_m: [0, 1], y_m: [0, 1], "
               "z_m: [10, 11], count: 3, redraw: false}\n")
    pose = preset_sonar().pose
    spec = make_setup(s).targets
    sets = [draw_targets(spec, p, pose) for p in range(200)]
    counts = np.array([(t.group == 0).sum() for t in sets])
    mean = 0.5 * 20
    assert abs(counts.mean() - mean) < 4 * math.sqrt(mean / 200)
    assert counts.var() == pytest.approx(mean, rel=0.35)  # Poisson: variance = mean
    fixed = [t.position_world_m[t.group == 1] for t in sets[:5]]
    assert all(np.array_equal(fixed[0], f) for f in fixed)
    moving = [t.position_world_m[t.group == 0][:1] for t in sets[:2]]
    assert not np.array_equal(moving[0], moving[1])


def test_world_frame_targets_follow_the_pose():
    s = _scene("name: w\nsonar:\n  pose: {position_m: [0, 0, 5], boresight: [1, 0, 0], receiver_axis: [0, 1, 0]}\n"
               "targets:\n  points:\n    - {frame: world, position_m: [20, 1, 5]}\n")
    from acoustics.sonar.build import build_sonar
    t = draw_targets(make_setup(s).targets, 0, build_sonar(s).pose)
    np.testing.assert_allclose(t.position_sonar_m[0], [1, 0, 20], atol=1e-12)


def test_arrivals_reject_strengths_of_another_length_in_one_line():
    son = preset_sonar()
    model = EchoModel(son.transmitter, son.receiver.elements, Medium(1530.0, 0.1), 420_375.0, 1.0)
    with pytest.raises(ValueError, match="positions_m and strength must describe the same scatterers"):
        arrivals(model, np.array([[0.0, 0.0, 20.0], [1.0, 0.0, 30.0]]), np.ones(3))
