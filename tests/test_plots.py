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
    """A ping index is a whole number, and so is a count of targets: every tick on either axis
    is one (matplotlib's default locator puts a 3-ping run's ticks at quarter pings, and counts
    of 2 to 17 at 2.5, 5.0, ...)."""
    import matplotlib.pyplot as plt

    from abacus.figures.plots import counts_figure
    x = np.arange(n_pings)
    c = {"ping_index": x, "true_in_volume": np.full(n_pings, 5), "count_before": np.where(x % 2, 17, 2),
         "count_after": np.full(n_pings, 5), "error_before": x - 1, "error_after": 0 * x}
    fig = counts_figure(c)
    fig.canvas.draw()
    for ax in fig.axes:
        for lim, got in ((ax.get_xlim(), ax.get_xticks()), (ax.get_ylim(), ax.get_yticks())):
            ticks = [t for t in got if lim[0] <= t <= lim[1]]   # pings, targets: whole numbers
            assert ticks, "no tick"
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


# ------------------------------------------------ calibrated scales, echogram orientation
def _figures_drawn(draw, *args):
    """Every figure ``draw(*args)`` saves, before it is closed: (figure, file name) pairs."""
    import matplotlib.figure
    seen, orig = [], matplotlib.figure.Figure.savefig

    def spy(fig, fname, *a, **k):
        seen.append((fig, str(fname)))
        return orig(fig, fname, *a, **k)
    matplotlib.figure.Figure.savefig = spy
    try:
        draw(*args)
    finally:
        matplotlib.figure.Figure.savefig = orig
    return seen


@pytest.fixture(scope="module")
def counted_default():
    """One ping of the default scene (noise on, detections inside and outside the span)."""
    import warnings

    import acoustics
    import processing
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return processing.count(acoustics.simulate(acoustics.load_scene("default"), pings=range(1)))


def test_a_unit_reflector_reads_0_db_ts_on_the_detection_figures_scale():
    """The point-target scene's reflector (ρ = 1 m: TS 0 dB re 1 m²) on the transmit axis: the
    brightest cell of the detection figure's TS image reads 0 dB within 0.5 dB (range-sampling
    and peak losses; echosounder calibrations are trusted to ~0.1 dB, abacus' compensated TS
    reads 0.2–0.4 dB low at these ranges, issue 28), and the colour bar says TS in dB re 1 m²."""
    import acoustics
    import processing
    from abacus.figures.calibrated import TS_LABEL
    from abacus.figures.plots import count_figure_data
    tree = processing.count(acoustics.simulate(acoustics.load_scene("point_target"), pings=range(1)))
    d = count_figure_data(tree, pings=[0], counts=False)["detections"][0]
    assert d["label"] == TS_LABEL
    assert abs(np.nanmax(d["values_db"]) - 0.0) < 0.5
    assert d["span_db"][0] < np.nanmax(d["values_db"]) <= d["span_db"][1]


def test_run_figures_are_calibrated_echograms_with_range_growing_downwards(counted_default, tmp_path):
    """Every image a run draws is in Sv (dB re 1 m⁻¹) or TS (dB re 1 m²), never "dB re max",
    with its ping in the title; every axis of range or depth grows downwards."""
    from abacus.figures.calibrated import echogram_calibration
    from abacus.figures.plots import (count_figure_data, draw_detection_figures, draw_image_figures,
                                      image_figure_data)
    from processing.records import figure_images
    im = figure_images(counted_default, [0])
    images = image_figure_data(im, calibration=echogram_calibration(counted_default, im))
    det = count_figure_data(counted_default, pings=[0])["detections"]
    seen = (_figures_drawn(draw_image_figures, images, tmp_path / "i")
            + _figures_drawn(draw_detection_figures, det, tmp_path / "c"))
    assert len(seen) == 5               # fan_beam, image, range_profiles, phase, detections_ping0
    scales, ranged = [], 0
    for fig, name in seen:
        for ax in fig.axes:
            label = ax.get_ylabel()
            scales += [label, ax.get_xlabel()] if ax.get_label() == "<colorbar>" else [ax.get_xlabel()]
            if "range" in label or "boresight" in label:
                ranged += 1
                assert ax.yaxis_inverted(), (name, label)
            if ax.get_label() != "<colorbar>" and ax.get_title() and "seen from" not in ax.get_title():
                assert "ping 0" in ax.get_title(), (name, ax.get_title())
    assert ranged >= 7                   # fan ×2, image ×2, profiles, phase, detections ×3
    db = [s for s in scales if "(dB" in s]         # the colour and value scales in dB
    assert len(db) >= 6 and all("dB re 1 m" in s for s in db), db


def test_the_detection_figure_says_what_the_counts_table_says(counted_default, tmp_path):
    """The figure's title gives the ping's detections, those in the counting span (the table's
    count before interferometry) and those in the counting volume (count after): the numbers of
    /Processing/Counts and /Processing/Detections, each."""
    import processing
    from abacus.figures.plots import count_figure_data, draw_detection_figures
    det = processing.detections_of(counted_default)
    cnt = processing.counts_of(counted_default)
    n = int((det["ping"].values == 0).sum())
    before, after = int(cnt["count_before"].values[0]), int(cnt["count_after"].values[0])
    assert before < n                    # some detections lie outside the span: the title says so
    seen = _figures_drawn(draw_detection_figures,
                          count_figure_data(counted_default, pings=[0])["detections"], tmp_path)
    title = seen[0][0].axes[0].get_title()
    assert f"ping 0: {n} detections" in title
    assert f"{before} in the counting span" in title and f"{n - before} outside it" in title
    assert f"{after} in the counting volume" in title


def test_track_ts_gives_each_counted_track_one_labelled_row(tmp_path):
    """track_ts.png: one row per counted track with a TS (the uncounted one and the one without
    a compensated TS have none), each labelled with its track and pings, its mean at the
    linear-domain mean of its detections' σ_bs (not the mean of the dB), on a TS axis."""
    import matplotlib.pyplot as plt
    import xarray as xr

    from abacus.figures.tracks import _track_ts_figure
    ts = np.array([-30.0, -40.0, -35.0, -35.0, -50.0, np.nan, np.nan])
    pt = np.array([0, 0, 1, 1, 2, 3, 3])
    mean = np.array([10 * np.log10(np.mean(10 ** (ts[pt == i] / 10))) if np.isfinite(ts[pt == i]).any()
                     else np.nan for i in range(4)])
    ds = xr.Dataset({"point_track": ("track_point", pt), "point_ts_comp": ("track_point", ts),
                     "track_ts": ("track", mean), "track_first_ping": ("track", [0, 2, 5, 7]),
                     "track_last_ping": ("track", [1, 3, 5, 8])})
    counted = np.array([True, True, False, True])
    seen = _figures_drawn(_track_ts_figure, ds, counted, plt.get_cmap("tab20"), tmp_path)
    ax = seen[0][0].axes[0]
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels == ["0 (pings 0–1)", "1 (pings 2–3)"]
    means = sorted(x for line in ax.lines if line.get_marker() == "o" for x in line.get_xdata())
    np.testing.assert_allclose(means, sorted([-32.596, -35.0]), atol=1e-3)   # 10 lg((10⁻³ + 10⁻⁴)/2)
    assert "dB re 1 m²" in ax.get_xlabel()
