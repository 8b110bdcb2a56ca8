"""Pulse compression, beamforming, images and interferometry (thesis chapter 4)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import processing
from acoustics import SceneWarning, load_scene
from acoustics.sonar.directivity import array_response, element_directivity
from acoustics.scene import scene_from_text
from acoustics.simulation.run import make_setup, simulate
from processing.imaging.beamforming import SubarrayGeometry, beamform_das, beamform_fft
from processing.imaging.compression import RangeFilter, compress, window
from processing.base.dataset import DatasetError, read_record
from processing.imaging.images import form_images
from processing.imaging.interferometry import elevation_from_phase, phase_from_elevation
from processing.detection.peaks import local_maxima, refine_peaks
from processing.settings import ImageSettings

from .conftest import LAMBDA_M, SCENES


def scene(name_or_text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        if name_or_text.endswith(".yaml"):
            return load_scene(SCENES / name_or_text)
        return scene_from_text(name_or_text)


def imaged(sc, settings=None):
    tree = processing.image(simulate(sc), settings)
    return tree, processing.images_of(tree)


def brightest(im, group=0, ping=0, rmin=None, rmax=None):
    mag = np.abs(im.image[ping, group])
    r = im.range_m
    sel = np.ones(r.size, bool)
    if rmin is not None:
        sel &= (r >= rmin) & (r <= rmax)
    sub = np.where(sel[:, None], mag, 0)
    i, j = np.unravel_index(np.argmax(sub), sub.shape)
    return i, j, mag


@pytest.fixture(scope="module")
def two():
    return imaged(scene("two_targets.yaml"))


def test_two_targets_at_true_range_and_azimuth(two):
    tree, im = two
    dr = np.median(np.diff(im.range_m))
    du = np.median(np.diff(np.sin(im.beam_angle_rad)))
    for g in range(2):
        for rng, az, lo, hi in ((17.0, 0.7, 16, 18), (21.0, -1.4, 20, 22)):
            i, j, _ = brightest(im, g, rmin=lo, rmax=hi)
            assert abs(im.range_m[i] - rng) <= dr + 1e-9  # ±1 range cell
            assert abs(np.sin(im.beam_angle_rad[j]) - math.sin(math.radians(az))) <= du / 2 + 1e-12


def test_image_is_calibrated_to_the_echo_amplitude():
    """A target on the 0° beam: image peak = echo amplitude at one element (independent model)."""
    sc = scene("name: cal\ntargets:\n  points:\n    - {range_m: 20, azimuth_deg: 0, elevation_deg: 0}\n"
               "processing:\n  image: {interpolation: 16, range_m: [19, 21]}\n")
    _, im = imaged(sc)
    i, j, mag = brightest(im)
    setup = make_setup(sc)
    p = np.array([[0.0, 0.0, 20.0]])
    k = setup.medium.wavenumber_rad_m(setup.pulse.center_frequency_hz)
    e_t = abs(array_response(setup.sonar.transmitter, p, wavenumber_rad_m=k)[0])
    rx = setup.sonar.receiver.elements
    d = element_directivity(rx, p, wavenumber_rad_m=k)[0]
    r1 = 20.0
    r2 = np.linalg.norm(rx.center_m - p, axis=1)
    alpha = setup.medium.absorption_db_per_m
    source = setup.sonar.transmitter.n_elements  # each unit-driven element: pressure 1 at 1 m
    a = 16384 * source * e_t * d / (r1 * r2) * 10 ** (-alpha * (r1 + r2) / 20)
    assert 20 * np.log10(mag.max() / a[:8].mean()) == pytest.approx(0.0, abs=0.1)


def test_elevation_of_a_target_at_0p3_degrees():
    sc = scene("name: el\ntargets:\n  points:\n    - {range_m: 20, azimuth_deg: 0.7, elevation_deg: 0.3}\n")
    _, im = imaged(sc)
    i, j, mag = brightest(im)
    # the cell's own elevation uses its beam angle; the target's refined azimuth removes the
    # bias that subarray B's x offset couples in (b_x Δsinθ / b_y, up to 0.07°)
    r_ref, az_ref, _ = refine_peaks(mag, [i], [j], im.range_m, im.beam_angle_rad)
    phi, clipped = elevation_from_phase(im.psi_rad[0, i, j], az_ref[0],
                                        im.baseline_m, LAMBDA_M)
    assert not np.any(clipped)
    assert abs(math.degrees(float(np.squeeze(phi))) - 0.3) < 0.05
    assert abs(math.degrees(az_ref[0]) - 0.7) < 0.05


def test_interferometric_phase_follows_the_thesis_sign():
    """ψ_AB = −(2π/λ) b sin φ for a baseline along +y (eq. 4.58)."""
    b = np.array([0.0, 0.0241, 0.0])
    phi = np.radians(np.linspace(-4, 4, 81))
    psi = phase_from_elevation(phi, 0.0, b, LAMBDA_M)
    np.testing.assert_allclose(psi, -2 * np.pi / LAMBDA_M * 0.0241 * np.sin(phi), atol=1e-12)
    back, clipped = elevation_from_phase(psi, np.zeros(81), b, LAMBDA_M)
    np.testing.assert_allclose(back, phi, atol=1e-12)
    assert not clipped.any()


def test_arcsin_argument_is_clipped_and_flagged_never_nan():
    b = np.array([0.0, LAMBDA_M / 4, 0.0])  # |s/R| reaches 2 for ψ = π
    psi = np.linspace(-np.pi, np.pi, 101)
    phi, clipped = elevation_from_phase(psi, np.zeros(101), b, LAMBDA_M)
    assert np.all(np.isfinite(phi))
    assert clipped.any() and not clipped.all()
    assert np.all(np.abs(phi[clipped]) == pytest.approx(np.pi / 2))
    with pytest.raises(ValueError, match="b_y"):
        elevation_from_phase(psi, np.zeros(101), np.zeros(3), LAMBDA_M)


def _peak_near(im, deg, width, *, group=0, rmin, rmax):
    mag = np.abs(im.image[0, group])
    r = im.range_m
    rows = (r >= rmin) & (r <= rmax)
    th = np.degrees(im.beam_angle_rad)
    cols = np.abs(th - deg) <= width
    sub = mag[np.ix_(rows, cols)]
    i, j = np.unravel_index(np.argmax(sub), sub.shape)
    return th[cols][j], sub.max() / mag.max()


def test_ghost_at_plus_7_for_a_target_at_minus_7():
    _, im = imaged(scene("ghost_grating_edge.yaml"))
    ang, rel = _peak_near(im, 7.0, 1.0, rmin=16, rmax=18)
    assert abs(ang - 7.0) <= 0.5
    assert rel > 0.5  # a grating lobe is as strong as the main lobe, not a sidelobe
    ang0, _ = _peak_near(im, -7.0, 1.0, rmin=16, rmax=18)
    assert abs(ang0 + 7.0) <= 0.5


def test_target_outside_the_scan_folds_to_one_degree_weakened_by_the_beams():
    _, ghost = imaged(scene("ghost_outside_scan.yaml"))
    direct_scene = scene(scene("ghost_outside_scan.yaml").resolved_text().replace(
        "azimuth_deg: 15.0", "azimuth_deg: 0.96"))
    _, direct = imaged(direct_scene)
    ang, _ = _peak_near(ghost, 1.0, 1.5, rmin=16, rmax=18)
    assert abs(ang - 1.0) <= 0.5
    g = np.abs(ghost.image[0, 0]).max()
    d = np.abs(direct.image[0, 0]).max()
    # what the ghost loses: the transmit beam (and the receive elements' own pattern) at 15°
    setup = make_setup(direct_scene)
    k = setup.medium.wavenumber_rad_m(setup.pulse.center_frequency_hz)
    p15 = 17 * np.array([[math.sin(math.radians(15)), 0, math.cos(math.radians(15))]])
    p1 = 17 * np.array([[math.sin(math.radians(0.96)), 0, math.cos(math.radians(0.96))]])
    tx = setup.sonar.transmitter
    tx_loss = abs(array_response(tx, p15, wavenumber_rad_m=k)[0] / array_response(tx, p1, wavenumber_rad_m=k)[0])
    rx = setup.sonar.receiver.elements.subset(range(8))
    rx_loss = (element_directivity(rx, p15, wavenumber_rad_m=k).mean()
               / element_directivity(rx, p1, wavenumber_rad_m=k).mean())
    assert g / d < tx_loss  # weaker than the direct target by at least the transmit-beam loss
    assert 20 * np.log10(g / d) == pytest.approx(20 * np.log10(tx_loss * abs(rx_loss)), abs=1.0)


def test_staggered_receiver_ghost_near_minus_3p4_and_none_without_stagger():
    sc = scene("ghost_stagger.yaml")
    flat = scene(sc.resolved_text().replace("receiver_stagger_m: 0.002", "receiver_stagger_m: 0.0"))
    _, im = imaged(sc)
    _, im0 = imaged(flat)
    # the stagger's contribution alone: a ghost arcsin(sin 3.5° − λ/2d) = −3.46° away
    diff = np.abs(im.image[0, 0] - im0.image[0, 0])
    ref = np.abs(im0.image[0, 0]).max()
    i, j = np.unravel_index(np.argmax(diff), diff.shape)
    expect = math.degrees(math.asin(math.sin(math.radians(3.5)) - LAMBDA_M / 0.03))
    assert abs(math.degrees(im.beam_angle_rad[j]) - expect) <= 0.5
    assert abs(expect + 3.4) < 0.1
    beta = 2 * math.pi / LAMBDA_M * 0.002 * math.sin(math.radians(1.0))
    assert 20 * np.log10(diff.max() / ref) == pytest.approx(20 * math.log10(math.tan(beta)), abs=1.0)
    # in the image itself: with the stagger something stands 8 dB above the flat array's floor
    _, with_st = _peak_near(im, -3.4, 0.8, rmin=23, rmax=25)
    _, without = _peak_near(im0, -3.4, 0.8, rmin=23, rmax=25)
    assert 20 * np.log10(with_st / without) > 8
    assert 20 * np.log10(without) < -30  # no ghost without the stagger: sidelobes only


def _cut_width(profile, axis, level=0.5 ** 0.5):
    i = int(np.argmax(profile))
    p = profile / profile[i]
    lo = i
    while lo > 0 and p[lo] > level:
        lo -= 1
    hi = i
    while hi < p.size - 1 and p[hi] > level:
        hi += 1
    f = lambda a, b: axis[a] + (level - p[a]) * (axis[b] - axis[a]) / (p[b] - p[a])  # noqa: E731
    return f(hi - 1, hi) - f(lo + 1, lo)


def test_point_target_response_widths_and_sidelobes():
    sc = scene("point_target.yaml")
    _, im = imaged(sc)
    i, j, mag = brightest(im)
    setup = make_setup(sc)
    # azimuth: the Hamming-weighted 8-element array factor x element pattern, evaluated directly
    rx = setup.sonar.receiver.elements.subset(range(8))
    th = im.beam_angle_rad
    x = rx.center_m[:, 0] - rx.center_m[:, 0].mean()
    w = window("hamming", 8)
    k = 2 * math.pi / LAMBDA_M
    af = np.abs((w[None, :] * np.exp(1j * k * np.outer(np.sin(th), x))).sum(1)) / w.sum()
    assert _cut_width(mag[i], th) == pytest.approx(_cut_width(af, th), rel=0.02)
    psl_meas = 20 * np.log10(np.sort(mag[i][np.abs(th) > np.radians(3)])[-1] / mag[i].max())
    psl_theory = 20 * np.log10(af[np.abs(th) > np.radians(3)].max())
    assert psl_meas == pytest.approx(psl_theory, abs=1.0)
    # range: the transform of the effective spectrum |U(f)|² W(f) (sqrt-Hann chirp x Hamming)
    rec = read_record(simulate(sc))
    from scipy.signal.windows import hamming
    nfft = 8192
    f = np.fft.fftfreq(nfft, 1 / rec.rate_hz)
    band = np.flatnonzero(np.abs(f) <= rec.bandwidth_hz / 2)
    band = band[np.argsort(f[band])]
    wdw = np.zeros(nfft)
    wdw[band] = hamming(band.size, sym=True)
    spec = np.abs(np.fft.fft(rec.replica, nfft)) ** 2 * wdw
    rf = type("F", (), {"nfft": nfft})
    up = 64
    big = np.zeros(rf.nfft * up)
    big[: rf.nfft // 2] = spec[: rf.nfft // 2]
    big[-(rf.nfft - rf.nfft // 2):] = spec[rf.nfft // 2:]
    pulse = np.abs(np.fft.ifft(big))
    t = np.arange(pulse.size) / (rec.rate_hz * up)
    pulse = np.roll(pulse, pulse.size // 2)
    width_theory = _cut_width(pulse, t) * 1530 / 2
    assert _cut_width(mag[:, j], im.range_m) == pytest.approx(width_theory, rel=0.03)
    # and it is the c/2B resolution broadened by the two tapers (between 1.5x and 2.5x)
    assert 1.5 < width_theory / (1530 / (2 * 20_000)) < 2.5


def test_fft_beamforming_equals_delay_and_sum_at_its_angles():
    rec = read_record(simulate(scene("two_targets.yaml")))
    rf = RangeFilter.design(rec.replica, n_samples=4096, rate_hz=rec.rate_hz, bandwidth_hz=rec.bandwidth_hz)
    y = compress(rec.samples[0], rf, upsample=2)[:, 2000:3000]
    idx = rec.image_groups["A"]
    geo = SubarrayGeometry(rec.element_position_m[idx], "hamming")
    angles, img_fft = beamform_fft(y[idx], geo, 32, rec.wavelength_m)
    img_das = beamform_das(y[idx], geo, angles, rec.wavelength_m)
    assert np.abs(img_fft - img_das).max() <= 1e-6 * np.abs(img_das).max()


@pytest.mark.parametrize("n_beams", [8, 9, 32])
def test_fft_beamforming_is_the_shifted_dft_with_the_phase_centre_correction(rng, n_beams):
    """beamform_fft gathers its beams instead of shifting the whole DFT: the same numbers as
    the textbook fftshift(DFT) · e^{−jk(x_0 − x_c) sin θ} / Σw (eq. 4.36–4.40), for any element
    order, an odd number of beams and a subset of beams."""
    order = rng.permutation(8)
    d = 0.6 * LAMBDA_M
    pos = np.zeros((8, 3))
    pos[:, 0] = d * order
    pos[:, 1] = 0.002
    y = rng.normal(size=(2, 8, 50)) + 1j * rng.normal(size=(2, 8, 50))
    geo = SubarrayGeometry(pos, "hamming")
    w = window("hamming", 8)
    spec = np.fft.fftshift(np.fft.fft(y[:, np.argsort(order)] * w[:, None], n_beams, axis=-2), axes=-2)
    x0 = geo.positions_m[0, 0] - geo.center_m[0]
    angles = np.arcsin((np.arange(n_beams) - n_beams // 2) * LAMBDA_M / (n_beams * d))
    corr = np.exp(-1j * 2 * np.pi / LAMBDA_M * x0 * np.sin(angles)) / w.sum()
    ref = np.swapaxes(spec * corr[:, None], -1, -2)
    got_angles, got = beamform_fft(y, geo, n_beams, LAMBDA_M)
    np.testing.assert_allclose(got_angles, angles, rtol=1e-12)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    beams = np.arange(2, n_beams - 1)
    out = np.empty((2, 50, beams.size), complex)
    sub_angles, sub = beamform_fft(y, geo, n_beams, LAMBDA_M, beams=beams, out=out)
    assert sub is out
    np.testing.assert_array_equal(sub, got[..., beams])
    np.testing.assert_array_equal(sub_angles, got_angles[beams])


@pytest.mark.parametrize("upsample", [1, 3, 4])
def test_interpolation_by_zero_padding_the_spectrum(rng, upsample):
    """to_time pads the band-limited spectrum with zeros (the two halves scaled by U) whatever
    the storage precision of the spectra."""
    from processing.imaging.compression import to_time
    rf = RangeFilter.design(np.exp(1j * rng.uniform(0, 6.3, 40)), n_samples=301, rate_hz=1e5,
                            bandwidth_hz=2e4)
    n = rf.nfft
    spec = (rng.normal(size=(3, n)) + 1j * rng.normal(size=(3, n))).astype(np.complex64)
    big = np.zeros((3, n * upsample), complex)
    h = (n + 1) // 2
    big[:, :h] = spec[:, :h]
    big[:, n * upsample - (n - h):] = spec[:, h:]
    ref = np.fft.ifft(big * upsample, axis=-1)
    got = to_time(spec, rf, upsample=upsample, keep=slice(5, 400))
    assert got.dtype == np.complex128
    np.testing.assert_allclose(got, ref[:, 5:400], rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_phase_centre_correction_removes_the_phase_slope_across_beams(two):
    """eq. 4.40: the phase of a target's cells no longer slopes with beam index. What is left is
    the wavefront's curvature over the 0.12 m aperture at 17 m (k x²/2r, quadratic, ~0.05 rad)."""
    _, im = two
    i, j, mag = brightest(im, 0, rmin=16, rmax=18)
    lobe = np.flatnonzero(mag[i] > 0.3 * mag[i, j])
    phase = np.unwrap(np.angle(im.image[0, 0, i, lobe] * np.conj(im.image[0, 0, i, j])))
    slope = np.polyfit(lobe - j, phase, 2)[1]  # coefficient of the linear term
    du = np.median(np.diff(np.sin(im.beam_angle_rad)))
    uncorrected = 2 * math.pi / LAMBDA_M * 7 * 0.015 / 2 * du  # the DFT's slope per beam
    assert uncorrected > 0.5
    assert abs(slope) < 0.02 * uncorrected
    assert np.abs(phase).max() < 0.1


def test_wideband_equals_narrowband_at_broadside_and_beats_it_off_axis():
    base = "name: wb\ntargets:\n  points:\n    - {range_m: 20, azimuth_deg: AZ, elevation_deg: 0}\n"
    for az in (0.0, 6.5):
        sc = scene(base.replace("AZ", str(az)))
        tree = simulate(sc)
        imgs = {}
        for bf in ("delay_and_sum", "wideband"):
            st = ImageSettings.model_validate({"beamformer": bf, "n_beams": 64, "range_m": [19, 21]})
            imgs[bf] = form_images(read_record(tree), st)
        a, b = np.abs(imgs["delay_and_sum"].image), np.abs(imgs["wideband"].image)
        if az == 0.0:
            # on the 0° beam (index 32) every delay is zero: identical
            np.testing.assert_allclose(a[..., 32], b[..., 32], rtol=1e-9, atol=1e-9 * b.max())
        else:
            assert b.max() >= a.max() * (1 - 1e-6)


def test_interpolation_keeps_peak_position_and_recovers_scalloping():
    tree = simulate(scene("two_targets.yaml"))
    res = {}
    for up in (1, 2, 4, 8):
        st = ImageSettings.model_validate({"interpolation": up})
        im = form_images(read_record(tree), st)
        mag = np.abs(im.image[0, 0])
        i = np.argmax(mag.max(axis=1))
        res[up] = (im.range_m[i], mag.max())
    for up in (2, 4, 8):
        assert abs(res[up][0] - res[1][0]) <= 0.0168 + 1e-9
        assert res[up][1] >= res[1][1] * 0.999
    assert res[8][1] / res[1][1] < 1.25  # a sample is never off the peak by more than ~1.9 dB


def test_local_maxima_hard_cases():
    assert local_maxima(np.zeros((0, 0)))[0].size == 0
    assert local_maxima(np.zeros((5, 4)))[0].size == 0  # an empty (zero) image has no peaks
    m = np.zeros((5, 4))
    m[0, 0] = 1.0  # on the edge
    m[3, 2] = m[3, 3] = 0.5  # a flat top: one peak
    r, c = local_maxima(m)
    assert list(zip(r, c)) == [(0, 0), (3, 2)]


def test_image_range_outside_the_record_is_a_clear_error():
    tree = simulate(scene("two_targets.yaml"))
    with pytest.raises(DatasetError, match="outside the record"):
        processing.image(tree, {"image": {"range_m": [100.0, 120.0]}})


def test_missing_groups_are_named():
    tree = simulate(scene("two_targets.yaml"))
    broken = tree.copy()
    del broken["Sonar"]
    with pytest.raises(DatasetError, match="/Sonar"):
        processing.image(broken)
