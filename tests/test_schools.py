"""Schools: the drawn fish have the density, spacing and polarisation the scene asks for."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from acoustics.scene import SceneWarning, scene_from_text
from acoustics.simulation.setup import make_setup
from acoustics.targets.draw import draw_targets
from acoustics.targets.schools import ellipsoid_axes, nearest_neighbour_m


def school(extra="", *, count="count: 400", nn=0.3, polarisation=0.9, seed=3):
    text = f"""name: school
seed: {seed}
medium: {{sound_speed_m_s: 1530}}
targets:
  populations:
    - kind: school
      center_m: [1.0, -2.0, 20.0]
      semi_axes_m: [4.0, 2.5, 1.5]
      heading_deg: 40
      {count}
      nearest_neighbour_m: {nn}
      redraw: false
      swim: {{speed_m_s: 0.6, heading_deg: 40, polarisation: {polarisation}}}
{extra}"""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        sc = scene_from_text(text)
    setup = make_setup(sc)
    return sc, draw_targets(setup.targets, 0, setup.pose_at(0))


def _ellipsoid_radius(t):
    """r_e = |A⁻¹ R⁻¹ (x − c)|: 1 on the ellipsoid's surface."""
    local = (t.position_world_m - np.array([1.0, -2.0, 20.0])) @ ellipsoid_axes(math.radians(40))
    return np.linalg.norm(local / np.array([4.0, 2.5, 1.5]), axis=1)


def test_every_fish_is_inside_and_uniform_in_the_ellipsoid():
    _, t = school()
    r = _ellipsoid_radius(t)
    assert len(t) == 400 and np.all(r <= 1.0 + 1e-12)
    # uniform in volume: half the fish inside the similar ellipsoid of radius 0.5^(1/3); the
    # binomial standard deviation is 0.025 for 400 fish (the hard core barely matters at 5 %)
    inner = np.mean(r < 0.5 ** (1 / 3))
    assert inner == pytest.approx(0.5, abs=0.08)


def test_no_two_fish_closer_than_the_nearest_neighbour_distance():
    _, t = school(nn=0.3)
    nn = nearest_neighbour_m(t.position_world_m)
    assert nn.min() >= 0.3
    # and the constraint binds: without it, 400 fish in 62.8 m³ have nearest neighbours near
    # 0.554 / n^(1/3) = 0.30 m on average (a Poisson process), many much closer
    _, free = school(nn=0.0)
    assert nearest_neighbour_m(free.position_world_m).min() < 0.3


def test_density_gives_the_expected_number_of_fish():
    """By density the count is Poisson(n V): over 20 seeds the mean is n V within 3 standard errors."""
    vol = 4.0 / 3.0 * math.pi * 4.0 * 2.5 * 1.5
    counts = [len(school(count="density_per_m3: 2.0", nn=0.1, seed=s)[1]) for s in range(20)]
    expected = 2.0 * vol
    assert np.mean(counts) == pytest.approx(expected, abs=3 * math.sqrt(expected / 20))


@pytest.mark.parametrize("polarisation", [0.0, 0.5, 0.9, 1.0])
def test_headings_have_the_requested_polarisation(polarisation):
    """The mean resultant length of 400 von Mises headings estimates ρ with a standard error
    below 0.035 (and a bias of ~1/√(πn) ≈ 0.03 at ρ = 0, the length of a random walk)."""
    _, t = school(polarisation=polarisation)
    h = np.arctan2(t.velocity_world_m_s[:, 1], t.velocity_world_m_s[:, 0])
    resultant = abs(np.mean(np.exp(1j * h)))
    assert resultant == pytest.approx(polarisation, abs=0.07)
    if 0.3 < polarisation < 1.0:
        # the mean direction's standard error is 1/√(n ρ κ); κ ≈ ρ(2 − ρ²)/(1 − ρ²) (Banerjee
        # et al.'s approximation, independent of the code's exact inversion): 3 standard errors
        kappa = polarisation * (2 - polarisation**2) / (1 - polarisation**2)
        tol = 3 * math.degrees(1 / math.sqrt(len(h) * polarisation * kappa))
        mean = math.degrees(np.angle(np.mean(np.exp(1j * h))))
        assert mean == pytest.approx(40.0, abs=tol)
    if polarisation == 1.0:
        np.testing.assert_allclose(np.degrees(h), 40.0, atol=1e-9)


def test_too_dense_a_school_is_refused():
    with pytest.raises(Exception, match="at most 25 %"):
        school(count="count: 5000", nn=0.5)


def test_the_batched_draw_is_sequential_rsa():
    """Against the textbook one-candidate-at-a-time RSA on the same candidate stream (batches of
    max(64, n) candidates, uniform in the ellipsoid): the same fish, in the same order."""
    from acoustics.scene.targets_spec import SchoolPopulation
    from acoustics.targets.schools import draw_school, ellipsoid_axes, uniform_in_ellipsoid
    spec = SchoolPopulation.model_validate({"kind": "school", "center_m": [1, 2, 20], "semi_axes_m": [3, 2, 1.5],
                                            "count": 300, "nearest_neighbour_m": 0.3, "redraw": False,
                                            "heading_deg": 25})
    rng = np.random.default_rng(11)
    kept = []
    while len(kept) < 300:
        for c in uniform_in_ellipsoid(300, spec.semi_axes_m, rng):
            if all(np.linalg.norm(c - k) >= 0.3 for k in kept):
                kept.append(c)
                if len(kept) == 300:
                    break
    expected = np.asarray(spec.center_m) + np.array(kept) @ ellipsoid_axes(spec.heading).T
    np.testing.assert_allclose(draw_school(spec, 300, np.random.default_rng(11)), expected, atol=1e-12)
