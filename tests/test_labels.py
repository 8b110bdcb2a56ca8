"""Label cubes (processing/imaging/labels.py): in the image of two targets under a flat sea, the
labels name each target's cell, its grating-lobe ghost and its surface ghosts as what they are
and whose they are — computed from the arrivals table through the image's own range and beam
responses, never by imaging a target alone."""
from __future__ import annotations

import numpy as np
import pytest

import acoustics
import processing
from acoustics.scene.load import scene_from_text
from processing.imaging.labels import CLASSES

CODE = {v: k for k, v in CLASSES.items()}

#: target A (id 0) at 17 m, −7°: its grating lobe images it again near +7°; target B (id 1) at
#: 21 m, +1.5°; both level with the sonar, 5 m under a pressure-release sea (their surface
#: paths come ~1.5 m and ~1.8 m behind)
GHOSTS = """
schema_version: 1
name: two-targets-ghosts
seed: 30
sonar:
  pose: {position_m: [0.0, 0.0, 5.0], boresight: [1.0, 0.0, 0.0], receiver_axis: [0.0, 1.0, 0.0]}
medium: {sound_speed_m_s: 1500.0}
targets:
  points:
    - {frame: world, position_m: [16.8733, -2.0718, 5.0], label: A}
    - {frame: world, position_m: [20.9928, 0.5497, 5.0], label: B}
boundaries:
  - name: sea surface
    role: surface
    mesh: {shape: plane, center_m: [20.0, 0.0, 0.0], normal: [0.0, 0.0, 1.0], size_m: [80.0, 40.0]}
effects: {max_bounces: 1, arrivals: {enabled: true}}
processing:
  image: {range_m: [15.0, 25.0], beamformer: delay_and_sum, azimuth_span_deg: 15.0, n_beams: 121}
"""


@pytest.fixture(scope="module")
def labelled():
    tree = acoustics.simulate(scene_from_text(GHOSTS), pings=1)
    out = processing.image(tree, labels=True)
    return tree, out


def _peak_near(power, row, beam, dr=4, db=3):
    """The brightest cell within ±dr rows and ±db beams of (row, beam)."""
    r0, b0 = max(row - dr, 0), max(beam - db, 0)
    win = power[r0:row + dr + 1, b0:beam + db + 1]
    r, b = np.unravel_index(np.argmax(win), win.shape)
    return r0 + r, b0 + b


def _cell(im, delay_s, sin_az):
    return (int(np.argmin(np.abs(im.time_s - delay_s))),
            int(np.argmin(np.abs(np.sin(im.beam_angle_rad) - sin_az))))


def test_labels_name_targets_and_their_ghosts(labelled):
    tree, out = labelled
    arr = tree["Vendor_specific/Arrivals"].ds
    lab = out["Processing/Labels"].ds
    im = processing.images_of(out)
    power = np.abs(im.image[0, 0]) ** 2
    cls, ids = lab["label_class"].values[0, 0], lab["label_id"].values[0, 0]
    frac = lab["label_fraction"].values[0, 0]
    seq = arr["arrival_sequence"].values.astype(str)
    lam = im.wavelength_m
    eg = tree["Sonar/Beam_group1"].ds
    x = eg["element_x"].values[eg["element_subarray"].values.astype(str) == "A"]
    pitch = float(np.median(np.diff(np.sort(x))))
    checked = []
    for tid in (0, 1):
        own = arr["arrival_target_id"].values == tid
        for s, want in (("T", "target"), ("S-T", "multipath_ghost"), ("T-S", "multipath_ghost")):
            i = int(np.flatnonzero(own & (seq == s))[0])
            az, el = arr["arrival_azimuth"].values[i], arr["arrival_elevation"].values[i]
            r, b = _peak_near(power, *_cell(im, arr["arrival_delay"].values[i], np.sin(az) * np.cos(el)))
            assert CLASSES[int(cls[r, b])] == want, (tid, s)
            assert ids[r, b] == tid and frac[r, b] > 0.5, (tid, s)
            if s != "T":
                # an echo of the image, not a sidelobe: 20 dB above the same beam halfway back
                # to the direct echo
                r_direct = _cell(im, arr["arrival_delay"].values[own & (seq == "T")][0], 0.0)[0]
                assert power[r, b] > 100 * power[(r + r_direct) // 2, b], (tid, s)
            checked.append((tid, s))
    # A's grating lobe: sin θ = sin(−7°) + λ/d, inside the ±7.5° image
    i = int(np.flatnonzero((arr["arrival_target_id"].values == 0) & (seq == "T"))[0])
    u_ghost = np.sin(arr["arrival_azimuth"].values[i]) + lam / pitch
    assert abs(u_ghost) < np.sin(np.radians(7.5))
    r, b = _peak_near(power, *_cell(im, arr["arrival_delay"].values[i], u_ghost))
    assert CLASSES[int(cls[r, b])] == "grating_lobe_ghost" and ids[r, b] == 0
    r_t, b_t = _peak_near(power, *_cell(im, arr["arrival_delay"].values[i], np.sin(arr["arrival_azimuth"].values[i])))
    assert abs(10 * np.log10(power[r, b] / power[r_t, b_t])) < 3.0      # as bright as A itself
    assert len(checked) == 6


def test_expected_energy_follows_the_image(labelled):
    """Wherever one arrival dominates (≥ 99 % of the expected energy) within 30 dB of the image's
    peak — the targets, their sidelobes, their ghosts — the label's expected energy, from the
    arrivals table and the image's responses alone, is the image's energy to 0.5 dB (median
    0.1 dB: docs/accuracy.md, "Label cubes", has seven scenes)."""
    tree, out = labelled
    im = processing.images_of(out)
    power = np.abs(im.image[0, 0]) ** 2
    lab = out["Processing/Labels"].ds
    expected = lab["label_expected_power"].values[0, 0]
    single = (lab["label_fraction"].values[0, 0] > 0.99) & (power > 1e-3 * power.max())
    assert single.sum() > 1000
    err = np.abs(10 * np.log10(expected[single] / power[single]))
    assert np.all(err < 0.5) and np.median(err) < 0.1
    # the ghosts' rows too (A's surface ghost, 30 dB down, in the beams where it peaks)
    ghosts = single & (lab["label_class"].values[0, 0] == CODE["multipath_ghost"])
    assert ghosts.sum() > 50


def test_noise_cells_are_noise():
    """With receiver noise, cells far from every echo are labelled noise, their share near 1."""
    text = GHOSTS.replace("effects: {", "noise: {enabled: true}\neffects: {")
    out = processing.image(acoustics.simulate(scene_from_text(text), pings=1), labels=True)
    lab = out["Processing/Labels"].ds
    cls = lab["label_class"].values[0, 0]
    frac = lab["label_fraction"].values[0, 0]
    assert (cls == CODE["noise"]).mean() > 0.5
    assert np.median(frac[cls == CODE["noise"]]) > 0.99
    assert (cls == CODE["target"]).any()


def test_labels_need_arrivals():
    tree = acoustics.simulate(scene_from_text(GHOSTS.replace("arrivals: {enabled: true}", "doppler: false")),
                              pings=1)
    with pytest.raises(processing.DatasetError, match="--arrivals"):
        processing.image(tree, labels=True)


def test_cli_writes_labels_with_the_image(labelled, tmp_path, capsys):
    from abacus.cli.app import main
    from processing.base.dataset import open_tree, write_tree
    tree, _ = labelled
    write_tree(tree, tmp_path / "sim.nc")
    assert main(["image", str(tmp_path / "sim.nc"), "-o", str(tmp_path / "img.nc"), "--labels"]) == 0
    back = open_tree(tmp_path / "img.nc")
    lab = back["Processing/Labels"].ds
    assert lab["label_class"].shape == back["Processing"].ds["image_r"].shape
    assert set(np.unique(lab["label_class"].values)) <= set(CLASSES)


def test_doppler_moves_the_expected_peak_with_the_image():
    """A target closing at 2 m/s: the LFM's range–Doppler coupling moves its image peak by
    f_d T / B (c/2) ≈ 12 cm; the labels' expected energy peaks on the same row (their range
    response is the Doppler-shifted pulse's), to 0.5 dB."""
    text = (GHOSTS.replace("label: B}", "label: B, velocity_m_s: [-2.0, 0.0, 0.0]}")
            .replace("effects: {max_bounces: 1,", "effects: {doppler: true, max_bounces: 0,"))
    out = processing.image(acoustics.simulate(scene_from_text(text), pings=1), labels=True)
    im = processing.images_of(out)
    power = np.abs(im.image[0, 0]) ** 2
    expected = out["Processing/Labels"].ds["label_expected_power"].values[0, 0]
    r, b = np.unravel_index(np.argmax(power), power.shape)
    assert np.unravel_index(np.argmax(expected), expected.shape) == (r, b)
    assert abs(10 * np.log10(expected[r, b] / power[r, b])) < 0.5
    # the shift is real: the peak is rows away from the delay of the path itself
    arr = out["Vendor_specific/Arrivals"].ds
    own = arr["arrival_target_id"].values == 1
    assert abs(im.range_m[r] - 750.0 * arr["arrival_delay"].values[own][0]) > 0.05


def test_builtin_ghost_scene_outside_the_scan():
    """scenes/ghost_outside_scan.yaml: a target at 15°, outside the FFT beams' ±7°, folds into
    the image near 1° through a grating lobe; the image's brightest cell is labelled as that
    target's grating-lobe ghost."""
    tree = acoustics.simulate("ghost_outside_scan", pings=1, arrivals=True)
    out = processing.image(tree, labels=True)
    im = processing.images_of(out)
    power = np.abs(im.image[0, 0]) ** 2
    r, b = np.unravel_index(np.argmax(power), power.shape)
    lab = out["Processing/Labels"].ds
    assert abs(np.degrees(im.beam_angle_rad[b])) < 2.0
    assert CLASSES[int(lab["label_class"].values[0, 0, r, b])] == "grating_lobe_ghost"
    assert lab["label_id"].values[0, 0, r, b] == 0
