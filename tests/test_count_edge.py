"""count.volume_edge: the soft counting-volume edge (processing/detection/volume_edge.py).

The reference is analytic. Fish spread uniformly in elevation over [−L, L] across a counting
volume of half-width e, each located with a Gaussian elevation error of known σ (e − L and e
many σ apart). Per fish, with x the distance to a face in units of σ and two faces:

* the hard count's and the soft count's means are both the number inside, 2e / 2L per fish;
* mean squared error of the hard count (a fish counted on the wrong side):
  2 · 2σ ∫₀^∞ Φ(−x) dx / 2L = 2σ / (L √(2π));
* of the soft count (the posterior mean): 2 · σ ∫ Φ(t)(1 − Φ(t)) dt / 2L = σ / (L √π), 1/√2 of
  the hard count's;
* mean absolute error of the hard count: the same as its squared error (errors are 0 or ±1);
  of the soft count: 2 · σ ∫ 2Φ(t)(1 − Φ(t)) dt / 2L = 2σ / (L √π), √2 times the hard count's.
"""
from __future__ import annotations

import numpy as np
import pytest

from processing.base.config import ConfigError, validate_file
from processing.base.counting_volume import CountingVolume
from processing.detection.volume_edge import elevation_sd_rad, soft_weights
from processing.settings import ProcessingSettings

EDGE = np.radians(0.43)
SIGMA = np.radians(0.1)
SPREAD = EDGE + 8 * SIGMA            # L: fish uniform over ±L, 8 σ beyond each face
VOLUME = CountingVolume((10.0, 20.0), np.radians(5.0), EDGE)


def _positions(range_m, azimuth, elevation):
    return np.stack([range_m * np.cos(elevation) * np.sin(azimuth), range_m * np.sin(elevation),
                     range_m * np.cos(elevation) * np.cos(azimuth)], -1)


def _fish(n, seed=29):
    rng = np.random.default_rng(seed)
    phi = rng.uniform(-SPREAD, SPREAD, n)
    measured = phi + SIGMA * rng.standard_normal(n)
    pos = _positions(np.full(n, 15.0), np.zeros(n), measured)
    inside = (np.abs(phi) <= EDGE).astype(float)
    soft = soft_weights(VOLUME, pos, np.full(n, SIGMA))
    hard = VOLUME.contains(pos).astype(float)
    return inside, hard, soft


def test_soft_count_is_unbiased_and_has_the_least_squared_error():
    n = 400_000
    inside, hard, soft = _fish(n)
    per_fish = 2 * EDGE / (2 * SPREAD)
    for count in (hard, soft):
        err = count - inside
        # the mean error is zero within 4 standard errors; the mean count is the fraction inside
        assert abs(err.mean()) < 4 * err.std() / np.sqrt(n)
        assert abs(count.mean() - per_fish) < 4 * count.std() / np.sqrt(n) + 4 * inside.std() / np.sqrt(n)
    mse_hard = 2 * SIGMA / (SPREAD * np.sqrt(2 * np.pi))
    mse_soft = SIGMA / (SPREAD * np.sqrt(np.pi))
    mae_soft = 2 * SIGMA / (SPREAD * np.sqrt(np.pi))
    for sample, expected in ((hard - inside) ** 2, mse_hard), ((soft - inside) ** 2, mse_soft), \
            (np.abs(soft - inside), mae_soft):
        assert abs(sample.mean() - expected) < 5 * sample.std() / np.sqrt(n)
    assert np.mean((soft - inside) ** 2) < np.mean((hard - inside) ** 2)
    # the price: the soft count's absolute error per fish is √2 times the hard count's
    assert np.mean(np.abs(soft - inside)) > np.mean(np.abs(hard - inside))


def test_count_of_many_fish_scatters_less_with_the_soft_edge():
    """Summed over 40 fish a ping, the count's error variance is 40 × the per-fish squared
    error: the soft count's ≈ 1/√2 of the hard count's."""
    inside, hard, soft = _fish(40 * 10_000, seed=30)
    per_ping = [(c - inside).reshape(-1, 40).sum(1) for c in (hard, soft)]
    var_hard, var_soft = (np.var(e) for e in per_ping)
    # the variance of a variance estimate from 10 000 pings of near-Gaussian sums: ≈ √(2/10 000)
    assert var_hard == pytest.approx(40 * 2 * SIGMA / (SPREAD * np.sqrt(2 * np.pi)), rel=0.06)
    assert var_soft == pytest.approx(40 * SIGMA / (SPREAD * np.sqrt(np.pi)), rel=0.06)
    assert var_soft / var_hard == pytest.approx(1 / np.sqrt(2), rel=0.09)


def test_zero_or_unknown_sigma_is_the_hard_rule():
    rng = np.random.default_rng(1)
    n = 5000
    pos = _positions(rng.uniform(8, 22, n), rng.uniform(-0.15, 0.15, n), rng.uniform(-0.02, 0.02, n))
    hard = VOLUME.contains(pos).astype(float)
    for sd in (0.0, np.nan, np.inf):
        assert np.array_equal(soft_weights(VOLUME, pos, np.full(n, sd)), hard)
    w = soft_weights(VOLUME, pos, np.full(n, SIGMA))
    assert np.all((w >= 0) & (w <= 1)) and np.all(w[~VOLUME.in_span(np.linalg.norm(pos, axis=1),
                                                                   np.arctan2(pos[:, 0], pos[:, 2]))] == 0)
    # deep inside the fan, many σ from either face, the weight is 1 to double precision
    centre = soft_weights(VOLUME, _positions(np.array([15.0]), np.zeros(1), np.zeros(1)), [EDGE / 40])
    assert centre[0] == 1.0
    assert soft_weights(VOLUME, np.zeros((0, 3)), np.zeros(0)).shape == (0,)


def test_elevation_sigma_is_the_cramer_rao_bound():
    """docs/validation.md's bound: ABACUS' baseline (7.5, 24.1, 0) mm, λ = 3.640 mm, image SNR
    30 dB (the detections' snr_db 3.01 dB higher), on axis: √(1/1000) λ / (2π b_y)."""
    b, lam = np.array([7.5e-3, 24.1e-3, 0.0]), 3.640e-3
    snr_db = 30 + 10 * np.log10(2)
    bound = np.sqrt(1e-3) * lam / (2 * np.pi * b[1])
    assert elevation_sd_rad([snr_db], [0.0], [0.0], baseline_m=b, wavelength_m=lam)[0] == pytest.approx(bound, rel=1e-12)
    assert np.degrees(bound) == pytest.approx(0.0435, abs=1e-4)   # the docs quote 0.0435°
    # an interference cap of 30 dB bounds a very strong echo's σ by the 30 dB value
    capped = elevation_sd_rad([200.0], [0.0], [0.0], baseline_m=b, wavelength_m=lam, interference_db=30.0)[0]
    assert capped == pytest.approx(bound, rel=1e-9)
    # off axis the phase slope is b_y cos φ − (b_x sin θ + b_z cos θ) sin φ
    th, ph = np.radians(5.0), np.radians(2.0)
    slope = b[1] * np.cos(ph) - b[0] * np.sin(th) * np.sin(ph)
    assert elevation_sd_rad([snr_db], [th], [ph], baseline_m=b, wavelength_m=lam)[0] == pytest.approx(
        np.sqrt(1e-3) * lam / (2 * np.pi * slope), rel=1e-12)
    assert np.isnan(elevation_sd_rad([np.nan], [0.0], [0.0], baseline_m=b, wavelength_m=lam)[0])
    # endfire: no elevation information, σ infinite (announced), not a division warning
    endfire = elevation_sd_rad([snr_db], [0.0], [0.0], baseline_m=[0, 0, 1e-2], wavelength_m=lam)
    assert np.isinf(endfire[0])


def test_setting_is_validated_in_one_line():
    for bad in ({"volume_edge": "fuzzy"}, {"edge_interference_db": -3}):
        with pytest.raises(ConfigError) as e:
            validate_file(ProcessingSettings, {"count": bad}, file="run.yaml")
        msg = str(e.value)
        assert f"count.{next(iter(bad))}" in msg and "\n" not in msg.strip()
    assert ProcessingSettings().count.volume_edge == "hard"


def test_counts_carry_the_expected_count_only_when_asked():
    """With "soft", /Processing/Counts holds count_expected and the density is its count over the
    volume; a detection more than 8 of its own σ inside the fan's faces counts 1 and one more than
    8 σ outside counts 0, so count_expected lies between the numbers of the first and of all but
    the second; it is the sum of the counted (not sidelobe) detections' probabilities of lying
    between the faces, σ from the record's own baseline and wavelength."""
    import warnings

    import acoustics
    import processing
    from acoustics.scene import scene_from_text
    from processing.pipeline import RecordChain
    from processing.detection.volume_edge import baseline_of
    scene = scene_from_text("""
schema_version: 1
name: soft-edge
seed: 1
sonar:
  pose: {position_m: [0.0, 0.0, 1.0], boresight: [0.0, 0.0, 1.0], receiver_axis: [0.0, 1.0, 0.0]}
  levels: {source_level_db: 210.0}
medium: {temperature_c: 10.0, salinity_psu: 35.0, depth_m: 20.0}
noise: {enabled: true, model: sea}
targets:
  populations:
    - kind: school
      center_m: [0.0, 0.0, 19.0]
      semi_axes_m: [1.2, 2.0, 2.0]
      density_per_m3: 2.0
      nearest_neighbour_m: 0.25
      random_phase: true
      backscatter: {model: swimbladder, length_m: 0.06, width_m: 0.01, tilt_sd_deg: 10.0}
pings: {count: 1}
processing:
  image: {range_m: [14.5, 23.5]}
  detect: {method: rayleigh, pfa_image: 1.0e-6, noise: {source: region, range_m: [14.5, 16.5], estimator: ml}}
  count: {range_m: [17.5, 20.5]}
""")
    settings = {"image": {"range_m": [14.5, 23.5]},
                "detect": {"method": "rayleigh", "pfa_image": 1.0e-6,
                           "noise": {"source": "region", "range_m": [14.5, 16.5], "estimator": "ml"}},
                "count": {"range_m": [17.5, 20.5], "volume_edge": "soft"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = processing.count(acoustics.simulate(scene))
        plain = processing.counts_of(tree)
        soft = processing.counts_of(processing.count(tree, settings))
        chain = RecordChain(tree, settings)
        det = chain.detected()
    assert "count_expected" not in plain and soft.attrs["volume_edge"] == "soft"
    expected = soft["count_expected"].values
    assert np.allclose(soft["density_per_m3"].values * soft.attrs["counting_volume_m3"], expected)
    t = det.table
    sd = elevation_sd_rad(t["snr_db"], t["azimuth_rad"], t["elevation_rad"], baseline_m=baseline_of(chain.record),
                          wavelength_m=chain.record.wavelength_m)
    counted = ~chain.sidelobes(det)
    assert counted.any() and np.isfinite(sd[counted & t["in_span"]]).all()
    pos = np.stack([t[f"{a}_m"] for a in "xyz"], -1)
    span = det.volume.in_span(np.linalg.norm(pos, axis=1), np.arctan2(pos[:, 0], pos[:, 2])) & counted
    el = np.abs(np.arctan2(pos[:, 1], np.hypot(pos[:, 0], pos[:, 2])))
    edge = det.volume.elevation_halfwidth_rad
    surely_in, maybe_in = span & (el < edge - 8 * sd), span & (el <= edge + 8 * sd)
    assert (maybe_in & ~surely_in).any()      # some detection's side of the face is in doubt
    low, high = (np.bincount(t["ping"][m], minlength=expected.size) for m in (surely_in, maybe_in))
    n = int(counted.sum())
    assert np.all(expected >= low - n * 1e-12) and np.all(expected <= high + n * 1e-12)
    # and it is the sum of the counted detections' probabilities of lying between the faces
    from scipy.stats import norm
    signed = np.arctan2(pos[:, 1], np.hypot(pos[:, 0], pos[:, 2]))
    p_in = np.where(span, norm.cdf((edge - signed) / sd) - norm.cdf((-edge - signed) / sd), 0.0)
    assert np.allclose(expected, np.bincount(t["ping"], weights=p_in, minlength=expected.size), atol=1e-9)
    assert np.array_equal(soft["count_after"].values, plain["count_after"].values)
