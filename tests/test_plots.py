"""Figures show the data where they are: the fan-beam resampling is exact where bilinear
interpolation must be, and axes are ticked in the units their quantity comes in."""
from __future__ import annotations

import numpy as np
import pytest

from abacus.figures.plots import fan_beam


def test_fan_beam_is_exact_for_a_field_bilinear_in_range_and_sine():
    """FFT beams are uniform in sin θ and samples in range, so a field bilinear in (r, sin θ)
    is bilinear in the image's fractional indices, where bilinear interpolation is exact: every
    pixel inside the fan is the field at the pixel's (r, sin θ) to rounding (1e-12 of its span)."""
    range_m = np.linspace(2.0, 30.0, 701)
    sin_theta = np.linspace(-0.12, 0.12, 64)
    theta = np.arcsin(sin_theta)

    def field(r, s):
        return 1.0 + 0.3 * r - 40.0 * s + 2.5 * r * s

    values = field(range_m[:, None], sin_theta[None, :])
    x, z, img, inside = fan_beam(values, range_m, theta, pixel_m=0.05, with_mask=True)
    zz, xx = np.meshgrid(z, x, indexing="ij")
    expected = field(np.hypot(xx, zz), xx / np.hypot(xx, zz))
    span = values.max() - values.min()
    assert inside.sum() > 0.25 * inside.size
    np.testing.assert_allclose(img[inside], expected[inside], rtol=0, atol=1e-12 * span)
    assert np.all(img[~inside] == 0)


def test_fan_beam_puts_a_point_echo_where_it_is():
    """One bright cell at (r0, θ0): the brightest pixel lies at x = r0 sin θ0, z = r0 cos θ0,
    within one pixel in each direction (the cell's footprint spans several pixels)."""
    range_m = np.linspace(5.0, 25.0, 401)
    theta = np.arcsin(np.linspace(-0.12, 0.12, 64))
    mag = np.zeros((range_m.size, theta.size))
    i, j = 250, 47
    mag[i, j] = 1.0
    x, z, img = fan_beam(mag, range_m, theta, pixel_m=0.02)
    k = np.unravel_index(np.argmax(img), img.shape)
    assert abs(x[k[1]] - range_m[i] * np.sin(theta[j])) <= 0.02
    assert abs(z[k[0]] - range_m[i] * np.cos(theta[j])) <= 0.02


@pytest.mark.parametrize("n_pings", [1, 3, 7])
def test_counts_are_plotted_against_whole_pings(n_pings):
    """A ping index is a whole number: every tick on the ping axis is one (matplotlib's default
    locator puts a 3-ping run's ticks at quarter pings)."""
    import matplotlib.pyplot as plt

    from abacus.figures.plots import counts_figure
    x = np.arange(n_pings)
    c = {"ping_index": x, "true_in_volume": np.full(n_pings, 5), "count_before": x + 4,
         "count_after": np.full(n_pings, 5), "error_before": x - 1, "error_after": 0 * x}
    fig = counts_figure(c)
    fig.canvas.draw()
    for ax in fig.axes:
        lo, hi = ax.get_xlim()
        ticks = [t for t in ax.get_xticks() if lo <= t <= hi]
        assert ticks, "no tick on the ping axis"
        assert all(float(t).is_integer() for t in ticks), ticks
    plt.close(fig)


@pytest.mark.parametrize("scene", ["default", "point_target"])
def test_one_detection_figure_redrawn_per_ping_gives_each_ping_its_own_pixels(tmp_path, scene):
    """detections_ping<k>.png from one figure whose data change from ping to ping are the
    pixels of a figure made for each ping alone, through pings with and without detections
    (markers and legend removed, then made again) and changing limits; for a fan taller than
    wide (default) and one wider than tall (point_target: the colour bar and the equal aspect
    shrink the axes along the fan's larger side after the first ping's grid is chosen)."""
    from PIL import Image

    import acoustics
    import processing
    from abacus.figures.plots import count_figure_data, draw_detection_figures
    tree = processing.count(acoustics.simulate(acoustics.load_scene(scene), pings=range(3)))
    d0, d1, d2 = count_figure_data(tree, pings=range(3))["detections"]
    none = dict(d1, ping_index=7, fan_x_m=d1["fan_x_m"][:0], fan_z_m=d1["fan_z_m"][:0],
                position_m=d1["position_m"][:0], in_span=d1["in_span"][:0],
                in_volume=d1["in_volume"][:0])
    far = dict(d2, ping_index=8, position_m=d2["position_m"] * [1.0, 1.0, 1.6])
    sequence = [d0, none, d1, far, d2]
    assert len(d0["fan_x_m"]) and len(d1["fan_x_m"])
    together = draw_detection_figures(sequence, tmp_path / "together")
    alone = [draw_detection_figures([d], tmp_path / f"alone{k}")[0] for k, d in enumerate(sequence)]
    for a, b in zip(together, alone):
        assert a.name == b.name
        assert np.array_equal(np.asarray(Image.open(a)), np.asarray(Image.open(b))), a.name
