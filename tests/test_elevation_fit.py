"""``detect.elevation: fit``: the elevation of a fish whose echo merges with a neighbour's
(processing/detection/elevation_fit.py), on the simulator's echoes of point targets.

Two targets less than a resolution cell apart give one peak whose ψ_AB mixes both (glint); a
fit of two point responses to the A and B images separates them, and the component nearest the
peak carries its own target's elevation. An isolated target fits one point response (the fit is
not taken, the peak's phase stands)."""
from __future__ import annotations

import math
import warnings
from functools import lru_cache

import numpy as np

from acoustics import SceneWarning
from acoustics.scene import scene_from_text
from acoustics.simulation.run import simulate
from processing.base.dataset import read_record
from processing.detection.elevation_fit import fit_detections
from processing.detection.peaks import refine_peaks
from processing.imaging.images import form_images
from processing.imaging.interferometry import elevation_from_phase
from processing.settings import ImageSettings

SETTINGS = ImageSettings(range_m=(19.5, 20.5))


@lru_cache(maxsize=2)
def _images(points):
    text = ("name: glint\nseed: 3\nmedium: {sound_speed_m_s: 1530.0}\n"
            "sampling: {time_offset_s: 0.018, samples: 1024}\ntargets:\n  points:\n"
            + "".join(f"    - {{range_m: {r}, azimuth_deg: {a}, elevation_deg: {e}}}\n" for r, a, e in points))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        rec = read_record(simulate(scene_from_text(text)))
    return rec, form_images(rec, SETTINGS)


def _peak(im):
    ia = im.groups.index("A")
    mag = np.abs(im.image[0, ia])
    i, j = np.unravel_index(np.argmax(mag), mag.shape)
    rng, az, _ = refine_peaks(mag, [i], [j], im.range_m, im.beam_angle_rad)
    return np.array([0]), np.array([i]), np.array([j]), rng, az


def _true_elevation_at(psi, az, im, rec):
    return math.degrees(float(np.squeeze(elevation_from_phase(psi, az, im.baseline_m, rec.wavelength_m)[0])))


def test_two_targets_in_one_cell_are_separated_and_each_keeps_its_elevation():
    # 0.4 range cells (6.7 cm) and 0.8 azimuth cells (2.4°) apart, on either side of a thin fan
    near, far = (20.0, 0.3, 0.45), (20.027, 2.2, -0.6)
    rec, im = _images((near, far))
    ping, row, beam, rng, az = _peak(im)
    ia, ib = im.groups.index("A"), im.groups.index("B")
    psi_peak = np.angle(im.image[0, ia, row, beam] * np.conj(im.image[0, ib, row, beam]))
    el_peak = _true_elevation_at(psi_peak, az, im, rec)
    psi, az_fit, rg_fit, taken = fit_detections(im, rec, ping, row, beam, rng, az, np.array([np.inf]))
    assert taken[0]
    el_fit = _true_elevation_at(psi, az_fit, im, rec)
    # the component nearest the peak is one of the two targets, at its own place and elevation
    truth = min((near, far), key=lambda t: math.hypot((t[0] - rng[0]) / im.range_resolution_m,
                                                      math.radians(t[1]) - az[0]))
    assert abs(rg_fit[0] - truth[0]) <= 0.005
    assert abs(math.degrees(az_fit[0]) - truth[1]) <= 0.1
    assert abs(el_fit - truth[2]) <= 0.02
    # the peak's phase mixes both (what the fit is for)
    assert abs(el_peak - truth[2]) >= 0.1, (el_peak, el_fit, truth)


def test_an_isolated_target_keeps_the_peaks_phase():
    rec, im = _images(((20.0, 0.7, 0.3),))
    ping, row, beam, rng, az = _peak(im)
    psi, az_fit, rg_fit, taken = fit_detections(im, rec, ping, row, beam, rng, az, np.array([np.inf]))
    assert not taken.any()
    assert np.isnan(psi).all() and np.isnan(az_fit).all() and np.isnan(rg_fit).all()


def test_weak_or_unmeasured_detections_are_not_fitted():
    rec, im = _images(((20.0, 0.3, 0.45), (20.027, 2.2, -0.6)))
    ping, row, beam, rng, az = _peak(im)
    for snr in (20.0, np.nan):
        assert not fit_detections(im, rec, ping, row, beam, rng, az, np.array([snr]))[3].any()


def test_the_chain_applies_the_fit_as_detect_all_does_however_the_record_is_cut():
    """The chain's pooled path (candidates kept, images dropped, the fit on a second imaging)
    gives the detections that detecting every ping at once with the fit gives."""
    from processing.chain import detect_record
    from processing.detection.detect import detect_all
    from processing.pipeline import noise_band_of, resolve_settings, volume_of
    text = ("name: glint-noise\nseed: 5\nmedium: {sound_speed_m_s: 1530.0}\n"
            "sampling: {time_offset_s: 0.018, samples: 1024}\nnoise: {enabled: true}\n"
            "pings: {count: 3, interval_s: 0.25}\ntargets:\n  points:\n"
            "    - {range_m: 20.0, azimuth_deg: 0.3, elevation_deg: 0.45}\n"
            "    - {range_m: 20.027, azimuth_deg: 2.2, elevation_deg: -0.6}\n"
            "processing: {image: {range_m: [19.0, 21.0]}, detect: {noise: {source: image}}}\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = simulate(scene_from_text(text))
    st = resolve_settings(tree)
    st = st.model_copy(update={"detect": st.detect.model_copy(update={"elevation": "fit"})})
    rec = read_record(tree)
    im = form_images(rec, st.image, noise_band_hz=noise_band_of(tree))
    vol = volume_of(tree, st, image_range_m=(im.range_m[0], im.range_m[-1]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = detect_all(im, rec, st.detect, vol, upsample=im.interpolation)
        det, _ = detect_record(rec, st, vol, noise_band_hz=noise_band_of(tree), chunk_pings=1, workers=2)
        peak = detect_all(im, rec, st.detect.model_copy(update={"elevation": "peak"}), vol,
                          upsample=im.interpolation)
    # the fit moved something (the merged pair's peak), and the chain moved the same
    assert not np.array_equal(ref.table["psi_rad"], peak.table["psi_rad"])
    for k, v in ref.table.items():
        np.testing.assert_array_equal(det.table[k], v, err_msg=k)


def test_a_fitted_component_outside_the_fitted_patch_is_not_taken():
    """The fit sees ±1.5 range cells × ±2 beams around the peak; a component it places outside
    that patch is an extrapolation the data there do not constrain (here a sidelobe cell at the
    image's corner, whose two-target fit puts its nearest component on the pair 1.9 cells and
    4.6° away). The detection is its own peak's echo: where the nearest component lies outside
    the patch, the peak's phase and position stand."""
    rec, im = _images(((20.0, 0.3, 0.45), (20.027, 2.2, -0.6)))
    nr, nb = im.image.shape[2:]
    dr = im.range_resolution_m
    step = float(im.range_m[1] - im.range_m[0])
    half = max(1, int(round(1.5 * dr / step)))
    for r, b in ((nr - 1, nb - 1), (0, nb - 1), (nr // 2, 0)):
        rows, beams = slice(max(r - half, 0), min(r + half + 1, nr)), slice(max(b - 2, 0), min(b + 3, nb))
        psi, az, rg, taken = fit_detections(im, rec, np.array([0]), np.array([r]), np.array([b]),
                                            im.range_m[[r]], im.beam_angle_rad[[b]], np.array([np.inf]))
        if taken[0]:
            assert im.range_m[rows][0] - 1e-9 <= rg[0] <= im.range_m[rows][-1] + 1e-9, (r, b, rg[0])
            lo, hi = np.sort(np.sin(im.beam_angle_rad[beams]))[[0, -1]]
            assert lo - 1e-12 <= np.sin(az[0]) <= hi + 1e-12, (r, b, np.degrees(az[0]))
