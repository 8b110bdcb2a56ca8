"""count.coincidence_correction: the expected number of fish behind a count of echoes, when fish
sharing a resolution cell give one echo (processing/detection/coincidence.py).

The reference is independent of the formula: fish drawn uniformly in a counting volume, merged
into one echo whenever two lie within ``unresolved_cells`` cells of each other in the image
(single linkage, in the scoring's cell metric), and the echoes counted."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from processing.base.config import ConfigError, validate_file
from processing.base.counting_volume import CountingVolume
from processing.detection.coincidence import coincidence_coefficient, corrected_count
from processing.settings import ProcessingSettings

DR, DTH, U = 0.05, 0.02, 1.5
VOLUME = CountingVolume((10.0, 30.0), 0.5, 0.01)


def _echoes(rng, n):
    """Number of echoes of n fish uniform in VOLUME: clusters of fish closer than U cells."""
    r = rng.uniform(VOLUME.range_m[0] ** 3, VOLUME.range_m[1] ** 3, n) ** (1 / 3)
    th = rng.uniform(-VOLUME.azimuth_halfwidth_rad, VOLUME.azimuth_halfwidth_rad, n)
    # the scoring's metric: Δr / δr and r Δsin θ / (r δθ)
    pairs = cKDTree(np.c_[r / DR, np.sin(th) / DTH]).query_pairs(U, output_type="ndarray")
    if len(pairs) == 0:
        return n
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(g, directed=False)[0]


@pytest.mark.parametrize("loss", [0.1, 0.2])
def test_corrected_count_recovers_uniform_fish(loss):
    """With a·N = 0.1 and 0.2 the echoes are 10 % and 18 % fewer than the fish; the corrected
    count is the number of fish to 1.5 % (the model's neglected terms: a third fish in one
    cluster in 2-D, and fewer neighbours at the volume's edges, each of order (aN)²/2 of N or
    less; the Monte-Carlo error over 60 draws is ~0.1 %)."""
    a = coincidence_coefficient(VOLUME, range_resolution_m=DR, azimuth_resolution_rad=DTH, unresolved_cells=U)
    n = int(round(loss / a))
    rng = np.random.default_rng(29)
    d = np.array([_echoes(rng, n) for _ in range(60)], float)
    assert d.mean() < n * (1 - 0.8 * loss)          # the loss is there to correct
    assert abs(corrected_count(d, a).mean() - n) <= 0.015 * n


def test_coefficient_is_half_the_exclusion_volume_over_the_volume():
    """a = π u² δr δθ ⟨r²⟩ 2 sin φ_h / (2V): for a thin shell at r0 ⟨r²⟩ → r0², V → r0² Δr 2θ_h 2 sin φ_h,
    so a → π u² δr δθ / (2 Δr 2θ_h) = (π u² / 2) / (number of cells)."""
    thin = CountingVolume((20.0, 20.5), 0.1, 0.01)
    a = coincidence_coefficient(thin, range_resolution_m=DR, azimuth_resolution_rad=DTH, unresolved_cells=U)
    cells = (0.5 / DR) * (0.2 / DTH)
    assert a == pytest.approx(np.pi * U ** 2 / 2 / cells, rel=1e-3)


def test_small_counts_and_limits():
    a = 0.01
    d = np.array([0.0, 1.0, 2.0, 5.0])
    n = corrected_count(d, a)
    # N̂ = D (1 + x + 3/2 x² + 8/3 x³ + …), x = aD (the series of −W₀(−x)); the next term 125/24 x⁴ < 1e-4
    x = a * d
    assert np.allclose(n, d * (1 + x + 1.5 * x ** 2 + 8 / 3 * x ** 3), rtol=1e-4)
    # saturation: beyond aD = 1/e the count no longer grows with the fish; capped at 1/a, finite
    sat = corrected_count([1.0 / (np.e * a), 100.0, 1000.0], a)
    assert np.allclose(sat, 1.0 / a, rtol=1e-6) and np.isfinite(sat).all()
    # no interferometry (NaN) passes through; a = 0 is the identity
    assert np.isnan(corrected_count([np.nan], a)[0])
    assert corrected_count(d, 0.0).tolist() == d.tolist()
    empty = CountingVolume((20.0, 20.0), 0.1, 0.01)
    assert coincidence_coefficient(empty, range_resolution_m=DR, azimuth_resolution_rad=DTH) == 0.0


def test_setting_is_validated_in_one_line():
    with pytest.raises(ConfigError) as e:
        validate_file(ProcessingSettings, {"count": {"coincidence_correction": "occupancy"}}, file="run.yaml")
    msg = str(e.value)
    assert "count.coincidence_correction" in msg and "\n" not in msg.strip()
    assert ProcessingSettings().count.coincidence_correction == "none"


def test_counts_carry_the_corrected_count_only_when_asked():
    """With "poisson", /Processing/Counts holds count_corrected (≥ count_after, equal where no
    echo) and the density is its count over the volume; the default counts echoes alone."""
    import warnings

    import acoustics
    import processing
    from acoustics.scene import scene_from_text
    scene = scene_from_text("""
schema_version: 1
name: coincidence
seed: 1
sonar:
  pose: {position_m: [0.0, 0.0, 1.0], boresight: [0.0, 0.0, 1.0], receiver_axis: [0.0, 1.0, 0.0]}
medium: {temperature_c: 10.0, salinity_psu: 35.0, depth_m: 20.0}
noise: {enabled: false}
targets:
  populations:
    - kind: school
      center_m: [0.0, 0.0, 19.0]
      semi_axes_m: [1.2, 2.0, 2.0]
      density_per_m3: 2.0
      nearest_neighbour_m: 0.25
      backscatter: {model: swimbladder, length_m: 0.06, width_m: 0.01}
pings: {count: 2, interval_s: 0.25}
processing:
  image: {range_m: [16.5, 21.5]}
  count: {range_m: [17.5, 20.5]}
""")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = acoustics.simulate(scene)
        plain = processing.counts_of(processing.count(tree))
        corr = processing.counts_of(processing.count(
            tree, {"image": {"range_m": [16.5, 21.5]},
                   "count": {"range_m": [17.5, 20.5], "coincidence_correction": "poisson"}}))
    assert "count_corrected" not in plain
    d, n = corr["count_after"].values, corr["count_corrected"].values
    assert (d > 0).any()
    assert np.all(n >= d) and np.all(n[d == 0] == 0) and np.all(n[d > 0] > d[d > 0])
    assert np.allclose(corr["density_per_m3"].values * corr.attrs["counting_volume_m3"], n)
    assert corr.attrs["coincidence_correction"] == "poisson"
