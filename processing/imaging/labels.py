"""Label cubes: what made each cell of an image, from the arrivals table (simulated data).

For every (ping, range cell, beam) of an image the label says which arrival of
/Vendor_specific/Arrivals (docs/dataset.md, "Arrivals") contributes the most energy, what
fraction of the cell's expected energy that is, and a class. Nothing is re-simulated: each
arrival's expected contribution to each cell follows from the arrival's amplitude, delay and
legs and the image's *known* responses (the element geometry the dataset carries, as the TS
compensation reads it: processing/backscatter/target_strength.py), written out for one path:

    P_a(r, b) = |G a E_t(P_tx) D(û_arr) B_b(P_rx) χ(t_r − τ_a)|²      (ADC counts²)

with a the arrival's complex amplitude (re the source level at 1 m), G = k Σ w_e the counts
per unit amplitude of one element on the transmitter's axis, E_t the transmitter's field at the
(image) scatterer P_tx = T + r1 û_dep, its elements summed at their exact distances (the near
field: a target two Rayleigh distances away in a null of the far-field pattern is 30 dB off
without it), D the receive element pattern (1 on axis), B_b the beam's response to the exact
spherical front from P_rx = R + r2 û_arr (the image's own spatial window, 1 on its axis: the
images are calibrated to the echo amplitude at one element),
χ the compressed pulse (the image's own range filter, 1 at its peak), t_r the row's two-way
delay and τ_a the arrival's delay to the image group's phase centre (a Doppler-shifted
arrival's χ is the shifted pulse's through the same filter: an LFM's range–Doppler coupling
moves its peak). Receiver noise adds
2σ² × the image's noise power gain to every cell. Arrivals are summed in power (their phases
are not modelled: the fraction is the share of the expected energy).

Classes (:data:`CLASSES`): ``noise`` where the noise power exceeds every arrival's; else by the
dominant arrival — ``target`` (a target's direct path, the cell's beam within the main lobe of
its direction, or in its sidelobes), ``grating_lobe_ghost`` (a direct path seen through a
grating lobe of the beam: the beam's sin θ differs from the arrival's by a multiple of λ/d,
within λ/(N d)), ``multipath_ghost`` (a target's path with a specular bounce), ``surface``,
``floor`` and ``obstacle`` (a boundary facet's backscatter). A ghost's id is its target's.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from processing.imaging.beamforming import SubarrayGeometry
from processing.imaging.compression import RangeFilter

__all__ = ["CLASSES", "LabelCube", "label_cube", "range_response", "labels_dataset"]

#: class code -> name (``label_class`` values)
CLASSES = {0: "noise", 1: "target", 2: "surface", 3: "floor", 4: "multipath_ghost",
           5: "grating_lobe_ghost", 6: "obstacle"}
_CODE = {v: k for k, v in CLASSES.items()}


@dataclass(frozen=True)
class LabelCube:
    """Labels of every cell of one image group.

    Attributes
    ----------
    source_id : ndarray of int64, shape (n_pings, n_range, n_beams)
        The dominant contributor's id: its target's ``target_id`` (a ghost's too), −1 for a
        boundary facet or noise.
    arrival : ndarray of int64, shape (n_pings, n_range, n_beams)
        Row of the arrivals table of the dominant arrival (−1 where noise dominates).
    fraction : ndarray of float32, shape (n_pings, n_range, n_beams)
        Its share of the cell's expected energy (arrivals and noise), 0–1.
    label_class : ndarray of int8, shape (n_pings, n_range, n_beams)
        :data:`CLASSES` code.
    expected_power : ndarray of float32, shape (n_pings, n_range, n_beams)
        The cell's expected energy, Σ_a P_a + noise (ADC counts²).
    """

    source_id: np.ndarray
    arrival: np.ndarray
    fraction: np.ndarray
    label_class: np.ndarray
    expected_power: np.ndarray


def range_response(rfilter: RangeFilter, upsample: int = 16, *, replica=None,
                   doppler_hz: float = 0.0):
    """|χ(t)| of the compressed pulse on a fine grid: (t in s, shape (m,); |χ|, shape (m,)), 1 at
    t = 0 without Doppler (the images' calibration).

    With ``doppler_hz`` ≠ 0 (and the ``replica``, shape (M,)) the echo is the replica shifted in
    frequency, u(t) e^{j2π f_d t}, through the same filter: an LFM's peak moves by f_d T/B
    (range–Doppler coupling) and drops a little; still re the unshifted peak."""
    n = rfilter.nfft
    if doppler_hz and replica is not None:
        rep = np.asarray(replica, complex)
        shifted = rep * np.exp(2j * np.pi * doppler_hz * np.arange(rep.size) / rfilter.rate_hz)
        spec = np.fft.fft(shifted, n) * rfilter.spectrum
        unshifted = np.fft.fft(rep, n) * rfilter.spectrum
    else:
        spec = unshifted = rfilter.response
    h = n // 2

    def fine(sp):
        big = np.zeros(n * upsample, complex)
        big[:h], big[n * upsample - (n - h):] = sp[:h], sp[h:]
        return np.abs(np.fft.fftshift(np.fft.ifft(big)))

    mag = fine(spec)
    norm = mag if spec is unshifted else fine(unshifted)
    t = (np.arange(n * upsample) - n * upsample // 2) / (rfilter.rate_hz * upsample)
    return t, mag / max(float(norm[n * upsample // 2]), 1e-300)


#: arrivals' Doppler shifts are taken on this grid for their range responses (Hz): 5 Hz moves an
#: ABACUS LFM's peak by 1.3 mm
DOPPLER_GRID_HZ = 5.0


def _unit(az, el):
    return np.stack([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)], -1)


def _classify(seq: np.ndarray) -> np.ndarray:
    """Class code of each arrival by its interaction sequence (direct targets: 1)."""
    out = np.full(seq.size, _CODE["target"], np.int8)
    for i, s in enumerate(seq):
        tokens = s.split("-")
        if tokens[0].startswith("R"):
            out[i] = {"RS": 2, "RF": 3}.get(tokens[0], 6)
        elif any(t in ("S", "F", "O") for t in tokens):
            out[i] = _CODE["multipath_ghost"]
    return out


def _accumulate(chunk, p_rx, peak, tau, geometry, steer, k, t_rows, t_chi, chi, lo_t, hi_t,
                total, flat_best, flat_arrival):
    """Add the arrivals ``chunk`` (sorted by delay) to one ping's cells: their energies to
    ``total`` (n_range, n_beams), and each cell's strongest so far to ``flat_best`` and
    ``flat_arrival`` (flat views)."""
    n_r, n_b = total.shape
    # each element's phase from the (image) source at its exact distance, re the phase
    # centre's: a plane wave far away, a curved front near the array
    dist = np.linalg.norm(p_rx[chunk, None, :] - geometry.positions_m[None, :, :], axis=2)
    ref = np.linalg.norm(p_rx[chunk] - geometry.center_m, axis=1)
    ph = np.exp(-1j * k * (dist - ref[:, None])) * (ref[:, None] / dist)          # (a, n_el)
    amp_b = peak[chunk, None] * np.abs((ph * geometry.weights) @ steer) / geometry.weights.sum()
    first = np.searchsorted(t_rows, tau[chunk] + lo_t, "left")
    last = np.minimum(np.searchsorted(t_rows, tau[chunk] + hi_t, "right"), n_r)
    for w in range(int(np.max(last - first))):
        r = first + w
        idx = np.flatnonzero(r < last)
        if idx.size == 0:
            continue
        rr = r[idx]
        g = np.interp(t_rows[rr] - tau[chunk[idx]], t_chi, chi, left=0.0, right=0.0)
        pw = (amp_b[idx] * g[:, None]) ** 2                                      # (a', b)
        starts = np.flatnonzero(np.r_[True, rr[1:] != rr[:-1]])
        rows_u = rr[starts]
        total[rows_u] += np.add.reduceat(pw, starts, axis=0)
        top = np.maximum.reduceat(pw, starts, axis=0)                            # (runs, b)
        run = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, idx.size]))
        pos = np.where(pw == top[run], np.arange(idx.size)[:, None], idx.size)
        who = chunk[idx][np.minimum.reduceat(pos, starts, axis=0)]               # (runs, b)
        cells = rows_u[:, None] * n_b + np.arange(n_b)
        better = top > flat_best[cells]
        flat_best[cells[better]] = top[better]
        flat_arrival[cells[better]] = who[better]


def label_cube(*, time_s, beam_angle_rad, phase_center_m, geometry: SubarrayGeometry,
               wavelength_m: float, rfilter: RangeFilter, arrivals: dict, ping_index,
               receive_reference_m, transmit_reference_m, gain_counts: float, transmit_pattern,
               receive_pattern, replica=None,
               noise_power_counts2: float = 0.0, floor_db: float = -60.0,
               sound_speed_m_s: float) -> LabelCube:
    """The label cube of one image group.

    Parameters
    ----------
    time_s : ndarray, shape (n_range,)
        Two-way delay of each image row (s).
    beam_angle_rad : ndarray, shape (n_beams,)
    phase_center_m : ndarray, shape (3,)
        The image group's phase centre (m, sonar frame).
    geometry : SubarrayGeometry
        The group's elements and spatial window, as the image was formed.
    wavelength_m : float
    rfilter : RangeFilter
        The image's range filter.
    replica : ndarray, shape (M,), optional
        The transmitted pulse: with it, each arrival's ``doppler`` (Hz) shifts and shapes its
        range response (an LFM's range–Doppler coupling); without, Doppler is ignored.
    arrivals : dict of str to ndarray
        The arrivals table's columns without the ``arrival_`` prefix (``ping_index``,
        ``target_id``, ``sequence``, ``delay``, ``amplitude_r``, ``amplitude_i``,
        ``departure_azimuth``, ``departure_elevation``, ``azimuth``, ``elevation``,
        ``transmit_range``, ``receive_range``), each (A,).
    ping_index : ndarray of int, shape (n_pings,)
        The image's pings (the arrivals' ``ping_index`` values).
    receive_reference_m, transmit_reference_m : ndarray, shape (3,)
        Where the arrivals' receive legs end and transmit legs start (the table's attributes).
    gain_counts : float
        G: counts at one element per unit amplitude on the transmitter's axis.
    transmit_pattern : callable
        |E_t(P)| at points (n, 3) (``BeamPattern.transmit_at``: the near field exactly).
    receive_pattern : callable
        |D(û)| for unit directions (n, 3) (``BeamPattern.receive``).
    noise_power_counts2 : float
        Expected noise power of an image cell (counts²; 0 without noise).
    floor_db : float
        Contributions below this (dB re the arrival's own peak) are left out (the pulse's far
        sidelobes).
    sound_speed_m_s : float

    Returns
    -------
    LabelCube
    """
    t_rows = np.asarray(time_s, float)
    theta = np.asarray(beam_angle_rad, float)
    n_r, n_b = t_rows.size, theta.size
    pings = np.asarray(ping_index, np.int64)
    shape = (pings.size, n_r, n_b)
    best = np.zeros(shape)
    arrival = np.full(shape, -1, np.int64)
    total = np.zeros(shape)
    seq = np.asarray(arrivals["sequence"]).astype(str)
    klass = _classify(seq)
    u_dep = _unit(np.asarray(arrivals["departure_azimuth"], float),
                  np.asarray(arrivals["departure_elevation"], float))
    u_arr = _unit(np.asarray(arrivals["azimuth"], float), np.asarray(arrivals["elevation"], float))
    amp = np.hypot(np.asarray(arrivals["amplitude_r"], float), np.asarray(arrivals["amplitude_i"], float))
    # delay to this group's phase centre: the plane wave reaches it earlier by û·(p_c − R)/c
    offset = (np.asarray(phase_center_m, float) - np.asarray(receive_reference_m, float))
    tau = np.asarray(arrivals["delay"], float) - (u_arr @ offset) / sound_speed_m_s
    # the legs' ends: the transmitter's field at the (image) scatterer, exactly (near field)
    r1 = np.asarray(arrivals["transmit_range"], float)
    r2 = np.asarray(arrivals["receive_range"], float)
    p_tx = np.asarray(transmit_reference_m, float) + r1[:, None] * u_dep
    p_rx = np.asarray(receive_reference_m, float) + r2[:, None] * u_arr
    peak = gain_counts * amp * transmit_pattern(p_tx) * receive_pattern(u_arr)
    # the array factor of every beam towards every arrival (the image's own weights)
    k = 2 * np.pi / wavelength_m
    x = geometry.positions_m - geometry.center_m
    u_beam = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], -1)
    ping_of = np.asarray(arrivals["ping_index"], np.int64)
    steer = np.exp(-1j * k * (x @ u_beam.T))                                # (n_el, b)
    doppler = np.asarray(arrivals.get("doppler", np.zeros(tau.size)), float)
    d_bin = np.round(doppler / DOPPLER_GRID_HZ).astype(np.int64) if replica is not None \
        else np.zeros(tau.size, np.int64)
    for b_hz in np.unique(d_bin):
        t_chi, chi = range_response(rfilter, replica=replica, doppler_hz=float(b_hz) * DOPPLER_GRID_HZ)
        support = t_chi[chi >= 10 ** (floor_db / 20)]
        lo_t, hi_t = float(support.min()), float(support.max())
        for pi, p in enumerate(pings):
            # this ping's arrivals that reach the image, in order of delay: for a given row
            # offset the rows they land on are then sorted, and those sharing a row are a run
            sel = np.flatnonzero((ping_of == p) & (d_bin == b_hz) & (peak > 0)
                                 & (tau + hi_t >= t_rows[0]) & (tau + lo_t <= t_rows[-1]))
            sel = sel[np.argsort(tau[sel], kind="stable")]
            for chunk in np.array_split(sel, max(1, sel.size // 4096)):
                if chunk.size:
                    _accumulate(chunk, p_rx, peak, tau, geometry, steer, k, t_rows, t_chi, chi,
                                lo_t, hi_t, total[pi], best[pi].reshape(-1),
                                arrival[pi].reshape(-1))
    noise = float(noise_power_counts2)
    power = total + noise
    noisy = noise >= best
    arrival[noisy] = -1
    frac = np.where(power > 0, np.where(noisy, noise, best) / np.where(power > 0, power, 1.0), 0.0)
    cls = np.zeros(shape, np.int8)
    has = arrival >= 0
    cls[has] = klass[arrival[has]]
    # a direct path seen through a grating lobe of the cell's beam
    pitch = float(np.median(np.diff(geometry.positions_m[:, 0]))) if geometry.n_elements > 1 else np.inf
    if np.isfinite(pitch) and pitch > 0:
        direct = has & (cls == _CODE["target"])
        idx = np.nonzero(direct)
        a = arrival[idx]
        du = u_arr[a, 0] - np.sin(theta[idx[2]])
        m = np.round(du * pitch / wavelength_m)
        aperture = pitch * geometry.n_elements
        ghost = (m != 0) & (np.abs(du - m * wavelength_m / pitch) < wavelength_m / aperture)
        cls[tuple(i[ghost] for i in idx)] = _CODE["grating_lobe_ghost"]
    tid = np.asarray(arrivals["target_id"], np.int64)
    source = np.full(shape, -1, np.int64)
    source[has] = tid[arrival[has]]
    return LabelCube(source, arrival, frac.astype(np.float32), cls, power.astype(np.float32))


def labels_dataset(tree, images, record, settings):
    """/Processing/Labels of a simulated dataset's images: one label cube per image group.

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset with /Vendor_specific/Arrivals (``abacus simulate --arrivals``).
    images : Images
        Its images (``image`` (n_pings, n_groups, n_range, n_beams)).
    record : SonarRecord
        The record they were formed from (element positions, replica).
    settings : ProcessingSettings

    Returns
    -------
    xarray.Dataset
        ``label_id``, ``label_arrival``, ``label_fraction``, ``label_class``,
        ``label_expected_power`` on (ping_time, image_group, image_range, beam).

    Raises
    ------
    processing.base.dataset.DatasetError
        The dataset has no arrivals table (named, with the command that writes one).
    """
    import xarray as xr

    from processing.backscatter.target_strength import beam_pattern_of
    from processing.base.contract import ARRIVALS_GROUP, ELEMENT_GROUP, SONAR_GROUP
    from processing.base.dataset import DatasetError, group_of
    arr = group_of(tree, ARRIVALS_GROUP)
    if arr is None:
        raise DatasetError(f"labels need the per-arrival ground truth /{ARRIVALS_GROUP}: simulate "
                           "with `abacus simulate --arrivals` (or effects.arrivals.enabled)")
    cols = {str(k)[len("arrival_"):]: arr[k].values for k in arr.data_vars}
    eg = group_of(tree, ELEMENT_GROUP)
    sonar = group_of(tree, SONAR_GROUP)
    scale = float(eg.attrs.get("adc_scale_counts", 1.0))
    gain = scale * float(np.sum(sonar["tx_element_weight"].values))
    sigma = float(eg.attrs.get("noise_sigma_counts", 0.0)) if int(eg.attrs.get("noise_enabled", 0)) else 0.0
    st = settings.image
    rf = RangeFilter.design(record.replica, n_samples=record.samples.shape[-1], rate_hz=record.rate_hz,
                            bandwidth_hz=record.bandwidth_hz, range_window=st.range_window)
    cubes = []
    for g in images.groups:
        idx = record.image_groups[g]
        geo = SubarrayGeometry(record.element_position_m[idx], st.spatial_window)
        pattern = beam_pattern_of(tree, g if g in ("A", "B") else "A")
        cubes.append(label_cube(
            time_s=images.time_s, beam_angle_rad=images.beam_angle_rad,
            phase_center_m=images.phase_centers_m[g], geometry=geo,
            wavelength_m=images.wavelength_m, rfilter=rf, arrivals=cols,
            ping_index=record.ping_index, receive_reference_m=np.asarray(arr.attrs["receive_reference_m"], float),
            transmit_reference_m=np.asarray(arr.attrs["transmit_reference_m"], float),
            gain_counts=gain, transmit_pattern=pattern.transmit_at, receive_pattern=pattern.receive,
            replica=record.replica,
            noise_power_counts2=2 * sigma ** 2 * images.noise_power_gain,
            sound_speed_m_s=record.sound_speed_m_s))
    dims = ("ping_time", "image_group", "image_range", "beam")

    def stack(name):
        return np.stack([getattr(c, name) for c in cubes], axis=1)

    return xr.Dataset(
        {"label_id": (dims, stack("source_id"), {"long_name": "dominant contributor: its target's "
                                                 "target_id (a ghost's too); -1 a boundary facet or noise"}),
         "label_arrival": (dims, stack("arrival"), {"long_name": "row of /Vendor_specific/Arrivals "
                                                    "of the dominant arrival; -1 noise"}),
         "label_fraction": (dims, stack("fraction"), {"units": "1", "long_name": "its share of the "
                                                      "cell's expected energy"}),
         "label_class": (dims, stack("label_class"), {
             "long_name": "class of the dominant contributor",
             "flag_values": np.array(list(CLASSES), np.int8),
             "flag_meanings": " ".join(CLASSES.values())}),
         "label_expected_power": (dims, stack("expected_power"), {
             "units": "ADC counts^2", "long_name": "expected energy of the cell: arrivals and noise"})},
        coords={"ping_time": tree[ELEMENT_GROUP].ds["ping_time"].values, "image_group": list(images.groups),
                "image_range": ("image_range", images.range_m, {"units": "m"}),
                "beam": np.arange(images.beam_angle_rad.size),
                "beam_angle": ("beam", images.beam_angle_rad, {"units": "rad"})},
        attrs={"classes": ", ".join(f"{k} {v}" for k, v in CLASSES.items()),
               "method": "expected energy of each arrival through the image's range and beam "
                         "responses (processing/imaging/labels.py)"})
