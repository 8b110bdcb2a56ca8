"""Assemble a simulation into the data contract (SONAR-netCDF4 1.0; processing/base/contract.py).

Values only: every group is made by :func:`processing.base.groups.build_group`, which takes the
dimensions, units and attributes of each variable from the contract's table.
"""
from __future__ import annotations

import datetime as _dt
import json
import platform
import sys

import numpy as np
import xarray as xr

from processing.base.contract import (BEAM_GROUP_NAME, CHANNEL, ELEMENT_GROUP, ENVIRONMENT_GROUP, PLATFORM_GROUP,
                                      PROVENANCE_GROUP, ROOT_GROUP, SONAR_GROUP, TRUTH_GROUP,
                                      ARRIVALS_GROUP)
from processing.base.groups import build_group, complex_pair, per_beam, per_ping, tree_of

from acoustics.frames import cartesian_to_spherical
from acoustics.sonar.calibration import sonar_calibration

__all__ = ["build_tree", "beam_group", "provenance_dataset", "versions", "rays_cast", "CHANNEL"]


def _element_geometry(elements, prefix: str) -> dict:
    """``<prefix>_x/_y/_z/_width/_height/_rotation`` of an ElementArray."""
    return {f"{prefix}_x": elements.center_m[:, 0], f"{prefix}_y": elements.center_m[:, 1],
            f"{prefix}_z": elements.center_m[:, 2], f"{prefix}_width": elements.width_m,
            f"{prefix}_height": elements.height_m, f"{prefix}_rotation": elements.rotation_rad}


def versions() -> dict:
    """Versions of everything that shapes the numbers."""
    import numba
    import scipy
    from acoustics import __version__
    return {"abacus": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__, "xarray": xr.__version__,
            "platform": platform.platform()}


def provenance_dataset(scene, seed: int, log, rays_cast: dict | None = None) -> xr.Dataset:
    """/Provenance: resolved scene, its sha256, the seed, versions, stages and their times.

    Parameters
    ----------
    scene : Scene
    seed : int
    log : StageLog
        The stages that ran, their calls and wall times (s).
    rays_cast : dict, optional
        Rays cast per purpose.

    Returns
    -------
    xarray.Dataset
        ``source_filenames`` along ``filenames``; the rest, the stages' wall times (s) and calls
        included (``stage_seconds_json``, ``stage_calls_json``), as attributes: two runs'
        timings differ by nature, and echopype combines files whose variables agree.
    """
    names = log.names
    return build_group(
        PROVENANCE_GROUP,
        {"source_filenames": [str(scene.source_path or scene.name)], "filenames": [0]},
        attrs={"scene_text": scene.resolved_text(), "scene_sha256": scene.sha256(),
               "scene_file": str(scene.source_path or ""), "seed": int(seed),
               "stages_run": ",".join(names),
               "stage_seconds_json": json.dumps({k: float(log.seconds[k]) for k in names}),
               "stage_calls_json": json.dumps({k: int(log.calls[k]) for k in names}),
               "versions": json.dumps(versions()),
               "rays_cast_json": json.dumps(rays_cast or {}),
               "command": " ".join(sys.argv),
               # what echopype's Provenance holds (combine_echodata reads it)
               "conversion_software_name": "abacus",
               "conversion_software_version": str(versions().get("abacus", "")),
               "conversion_time": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()})


def _ping_times(scene, pings):
    start = np.datetime64(scene.pings.start_time, "ns")
    step = np.timedelta64(int(round(scene.pings.interval_s * 1e9)), "ns")
    return start + np.asarray(pings, np.int64) * step


def build_tree(scene, setup, pings, samples, clipped, truth, log, seed, *,
               arrivals=None, rays=None) -> xr.DataTree:
    """The DataTree of one simulation run, every group made by the contract's builder
    (processing/base/contract.py has the layout).

    Parameters
    ----------
    scene : Scene
    setup : Setup
        What :func:`acoustics.simulation.setup.make_setup` made of the scene.
    pings : sequence of int, length n_pings
        The scene's ping indices.
    samples : (ndarray, ndarray)
        I and Q, each float32 of shape (n_pings, n_samples, n_elements) (ADC counts); wrapped,
        not copied.
    clipped : ndarray of int, shape (n_pings, n_elements), or None
        Samples the ADC clipped per element (None when it does not quantise).
    truth : list of TargetSet, length n_pings
        The targets of each ping.
    log : StageLog
    seed : int
    arrivals : list of dict, optional
        Each ping's arrivals table (acoustics/simulation/arrival_table.py): written as
        /Vendor_specific/Arrivals.
    rays : dict, optional
        Rays cast per purpose (:func:`rays_cast` of the run's cache).

    Returns
    -------
    xarray.DataTree
        /, /Environment, /Platform, /Provenance, /Sonar, /Sonar/Beam_group1, /Vendor_specific
        (and /Vendor_specific/Arrivals with ``arrivals``).
    """
    sonar, medium, pulse = setup.sonar, setup.medium, setup.pulse
    s = scene.sampling
    ping_time = _ping_times(scene, pings)
    rx = sonar.receiver
    chan_names = np.array([f"{sub}{idx}" for sub, idx in rx.channels])
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()

    model = "ABACUS" if scene.sonar.preset == "abacus" else "custom"
    # SONAR-netCDF4 1.0 (ICES CRR 341) top level (the convention's names are the contract's);
    # echopype reads ``keywords`` as the sonar model
    root = build_group(ROOT_GROUP, {}, attrs={
        "keywords": model,
        "title": f"abacus simulation: {scene.name}", "summary": scene.description.strip() or scene.name,
        "date_created": now, "software_name": "abacus",
        "software_version": versions()["abacus"], "data_kind": "simulated"})

    env = build_group(ENVIRONMENT_GROUP, {
        "sound_speed_indicative": medium.sound_speed_m_s,
        "absorption_indicative": [medium.absorption_db_per_m],
        "temperature": medium.temperature_c, "salinity": medium.salinity_psu,
        "depth": medium.depth_m, "ph": medium.ph,
        "frequency": [pulse.center_frequency_hz]})

    platform_ds = build_group(PLATFORM_GROUP, _platform(setup, pose=sonar.pose, pings=pings, scene=scene),
                              attrs=None if setup.platform is None else {"mount": (
                                  "sonar_position/sonar_rotation: the mounting pose at rest; "
                                  "ping_sonar_*: the pose of each ping")})

    tx = sonar.transmitter
    replica = pulse.replica(s.rate_hz)
    cal_gain, cal_az, cal_width = sonar_calibration(
        tx, sonar.receiver.elements, wavenumber_rad_m=setup.model.wavenumber_rad_m,
        scale_counts=setup.model.scale_counts)
    start, stop = _sweep_hz(pulse)
    sonar_ds = build_group(
        SONAR_GROUP,
        {"transmit_frequency_start": start, "transmit_frequency_stop": stop,
         "transmit_frequency_center": pulse.center_frequency_hz,
         "transmit_bandwidth": pulse.bandwidth_hz,
         "transmit_duration_nominal": pulse.duration_s,
         "beamwidth_transmit_major": np.degrees(setup.tx_beamwidth_az_rad),
         "beamwidth_transmit_minor": np.degrees(setup.tx_beamwidth_el_rad),
         **complex_pair("replica", replica),
         **_element_geometry(tx, "tx_element"),
         "tx_element_weight": tx.weight,
         "calibration_gain": cal_gain,
         "beam_group_name": [BEAM_GROUP_NAME],
         "beam_group_descr": ["complex baseband samples of every receive element: one beam per element "
                              "(docs/dataset.md, 'Beams are elements')"],
         "two_way_elevation_width": cal_width,
         "channel_all": [CHANNEL], "beam_group": [BEAM_GROUP_NAME], "replica_sample": np.arange(replica.size),
         "calibration_azimuth": cal_az},
        attrs={"taper": pulse.taper, "sweep": pulse.sweep,
               "sonar_manufacturer": "abacus (simulated)", "sonar_model": model,
               "sonar_serial_number": "", "sonar_software_name": "abacus",
               "sonar_software_version": versions()["abacus"],
               "variant": scene.sonar.variant if scene.sonar.preset == "abacus" else "explicit",
               "mode": rx.mode, "frame": "sonar frame: +z boresight, +x along the receiver, +y along the transmitter"})

    eg = beam_group(scene, setup, pings, ping_time, samples, clipped, chan_names,
                    psi_element_sr=float(np.trapezoid(cal_width, cal_az)))

    truth_ds = _truth(setup, pings, ping_time, truth)
    groups = {ROOT_GROUP: root, ENVIRONMENT_GROUP: env, PLATFORM_GROUP: platform_ds,
              PROVENANCE_GROUP: provenance_dataset(scene, seed, log, rays),
              SONAR_GROUP: sonar_ds, ELEMENT_GROUP: eg, TRUTH_GROUP: truth_ds}
    if arrivals is not None:
        groups[ARRIVALS_GROUP] = _arrivals(scene, setup, arrivals)
    return tree_of(groups)


def _arrivals(scene, setup, tables) -> xr.Dataset:
    """/Vendor_specific/Arrivals: every ping's arrivals, one row each."""
    from acoustics.simulation.arrival_table import ALPHABET, concat_tables
    cols = concat_tables(tables)
    floor = scene.effects.arrivals.floor_db
    return build_group(
        ARRIVALS_GROUP, {f"arrival_{k}": v for k, v in cols.items()},
        attrs={"alphabet": "; ".join(f"{k}: {v}" for k, v in ALPHABET.items()),
               "floor_db": "none" if floor is None else float(floor),
               "max_bounces": int(scene.effects.max_bounces),
               "transmit_reference_m": [float(x) for x in setup.model.transmitter.phase_center_m],
               "receive_reference_m": [float(x) for x in setup.model.receiver.phase_center_m]})


def _sweep_hz(pulse) -> tuple:
    """Start and stop frequencies (Hz) of the pulse's sweep (down-chirps start high)."""
    half = np.sign(pulse.chirp_rate_hz_s or 1) * pulse.bandwidth_hz / 2
    return pulse.center_frequency_hz - half, pulse.center_frequency_hz + half


def _platform(setup, *, pose, pings, scene) -> dict:
    """/Platform's values: the mounting pose and transducer offsets and, for a moving platform,
    the pose of every ping and the attitude (deg) and heave (m) it came from."""
    values = {"sonar_position": pose.position_m, "sonar_rotation": pose.rotation,
              "world_axis": ["x", "y", "z"], "sonar_axis": ["x", "y", "z"], "channel": [CHANNEL]}
    for k, a in enumerate("xyz"):   # SONAR-netCDF4's transducer offset: the sonar at rest
        values[f"transducer_offset_{a}"] = [pose.position_m[k]]
    if setup.platform is None:
        return values
    poses = [setup.pose_at(p) for p in pings]
    roll, pitch, yaw, heave = setup.platform.attitude(np.asarray(pings, float) * setup.interval_s)
    values["ping_sonar_position"] = np.stack([q.position_m for q in poses])
    values["ping_sonar_rotation"] = np.stack([q.rotation for q in poses])
    for name, v in (("roll", np.degrees(roll)), ("pitch", np.degrees(pitch)), ("heading", np.degrees(yaw)),
                    ("vertical_offset", np.asarray(heave, float))):
        values[name] = np.broadcast_to(v, (len(pings),)).copy()
    values["ping_time"] = _ping_times(scene, pings)
    return values


def _element_beamwidth_deg(size_m, wavelength_m):
    """3 dB full width (deg) of a baffled rectangular piston of this size: |sinc(w u/λ)| = 1/√2
    at w u/λ = 0.4429."""
    return np.degrees(2 * np.arcsin(np.minimum(0.4429 * wavelength_m / np.asarray(size_m, float), 1.0)))


def beam_group(scene, setup, pings, ping_time, samples, clipped, chan_names, *, psi_element_sr):
    """/Sonar/Beam_group1: the per-element samples as SONAR-netCDF4 lays out complex data in
    echopype (``backscatter_r/_i`` on (channel, ping_time, range_sample, beam)), one channel (the
    receiver) whose beams are its elements, with the beam-group variables of the convention and
    the element geometry processing needs.

    Parameters
    ----------
    scene, setup, pings, samples, clipped
        As :func:`build_tree` takes them.
    ping_time : ndarray of datetime64[ns], shape (n_pings,)
    chan_names : ndarray of str, shape (n_elements,)
        Element names (``A0`` ... ``B15``).
    psi_element_sr : float
        Two-way equivalent solid angle of the transmitter and one element (sr).

    Returns
    -------
    xarray.Dataset
    """
    sonar, pulse = setup.sonar, setup.pulse
    s = scene.sampling
    rx = sonar.receiver
    el = rx.elements
    n_p = len(pings)
    lam = setup.medium.sound_speed_m_s / pulse.center_frequency_hz
    rot = sonar.pose.rotation
    # each element faces the sonar's +z (rotations are about z): its direction in the platform frame
    direction = np.broadcast_to(rot @ np.array([0.0, 0.0, 1.0]), (el.n_elements, 3))
    start, stop = _sweep_hz(pulse)
    values = {
        # the samples are already float32 (ping_time, range_sample, beam) planes: wrapped, not
        # copied, and written as they are (a transposed view would be copied whole by the writer)
        **{f"backscatter_{k}": v[None] for k, v in zip("ri", samples)},
        "beam_type": ["single"],
        "beam_direction_x": per_beam(direction[:, 0]), "beam_direction_y": per_beam(direction[:, 1]),
        "beam_direction_z": per_beam(direction[:, 2]),
        "beamwidth_receive_major": per_beam(_element_beamwidth_deg(el.width_m, lam)),
        "beamwidth_receive_minor": per_beam(_element_beamwidth_deg(el.height_m, lam)),
        "beamwidth_transmit_major": per_beam(np.full(el.n_elements, np.degrees(setup.tx_beamwidth_az_rad))),
        "beamwidth_transmit_minor": per_beam(np.full(el.n_elements, np.degrees(setup.tx_beamwidth_el_rad))),
        "equivalent_beam_angle": per_beam(np.full(el.n_elements, 10 * np.log10(psi_element_sr))),
        "sample_interval": per_ping(1.0 / s.rate_hz, n_p),
        "blanking_interval": per_ping(s.time_offset_s, n_p),
        "sample_time_offset": per_ping(0.0, n_p),
        "transmit_frequency_start": per_ping(start, n_p), "transmit_frequency_stop": per_ping(stop, n_p),
        "transmit_duration_nominal": per_ping(pulse.duration_s, n_p),
        "transmit_bandwidth": per_ping(pulse.bandwidth_hz, n_p),
        "transmit_type": ["LFM"],
        "beam_stabilisation": np.zeros(n_p, np.int8),
        "non_quantitative_processing": np.zeros(n_p, np.int16),
        **_element_geometry(el, "element"),
        "element_subarray": rx.channel_subarray.astype(str),
        "element_index_in_subarray": np.array([i for _, i in rx.channels]),
        "channel": [CHANNEL], "ping_time": ping_time, "ping_index": np.asarray(pings, np.int64),
        "range_sample": np.arange(s.samples), "beam": chan_names}
    if clipped is not None:
        values["adc_clipped_samples"] = clipped
    return build_group(
        ELEMENT_GROUP, values,
        attrs={"mode": rx.mode, "adc_scale_counts": s.adc.scale_counts,
               "adc_quantized": int(s.adc.quantize), "adc_bits": s.adc.bits,
               "noise_enabled": int(scene.noise.enabled), "noise_sigma_counts": scene.noise.sigma_counts,
               "noise_bandwidth_hz": scene.noise.bandwidth_hz,
               "receiver_bandwidth_hz": s.receiver_bandwidth_hz, "beam_mode": "vertical",
               "conversion_equation_type": "none: samples are complex baseband in ADC counts"})


def rays_cast(cache) -> dict:
    """Rays cast per purpose in a run (its :class:`~acoustics.simulation.setup.RunCache`;
    empty without meshes)."""
    rs = cache.ray_scene
    return dict(rs.caster.rays_cast) if rs is not None else {}


def _truth(setup, pings, ping_time, truth) -> xr.Dataset:
    n = [len(t) for t in truth]
    ping_of = np.repeat(np.asarray(pings, np.int64), n)
    if sum(n):
        ps = np.concatenate([t.position_sonar_m for t in truth])
        pw = np.concatenate([t.position_world_m for t in truth])
        rho = np.concatenate([t.rho_m for t in truth])
        ph = np.concatenate([t.phase_rad for t in truth])
        grp = np.concatenate([t.group for t in truth])
        shd = np.concatenate([t.shadowed if t.shadowed is not None else np.zeros(len(t), bool) for t in truth])
        tid = np.concatenate([t.target_id if t.target_id is not None else np.full(len(t), -1) for t in truth])
        vel = np.concatenate([t.velocity_world_m_s if t.velocity_world_m_s is not None
                              else np.zeros((len(t), 3)) for t in truth])
    else:
        ps = pw = vel = np.zeros((0, 3))
        rho = ph = np.zeros(0)
        grp = tid = np.zeros(0, int)
        shd = np.zeros(0, bool)
    r, az, el = cartesian_to_spherical(ps)
    volume = setup.counting_volume
    inside = volume.contains(ps)
    with np.errstate(divide="ignore"):
        ts = np.where(rho > 0, 20 * np.log10(np.where(rho > 0, rho, 1.0)), -np.inf)
    return build_group(
        TRUTH_GROUP,
        {"target_ping_index": ping_of,
         "target_x": ps[:, 0], "target_y": ps[:, 1], "target_z": ps[:, 2],
         "target_world_x": pw[:, 0], "target_world_y": pw[:, 1], "target_world_z": pw[:, 2],
         "target_range": r, "target_azimuth": az, "target_elevation": el,
         "target_backscatter_amplitude": rho, "target_ts": ts, "target_phase": ph,
         "target_group": grp, "target_id": tid.astype(np.int64),
         "target_velocity_world_x": vel[:, 0], "target_velocity_world_y": vel[:, 1],
         "target_velocity_world_z": vel[:, 2],
         "target_in_counting_volume": inside.astype(np.int8),
         "target_shadowed": shd.astype(np.int8),
         "ping_time": np.repeat(np.asarray(ping_time), n)},
        attrs={"counting_volume": "transmitter 3 dB beam (azimuth, elevation) x image range limits",
               "counting_range_min_m": float(volume.range_m[0]),
               "counting_range_max_m": float(volume.range_m[1]),
               "counting_azimuth_halfwidth_rad": volume.azimuth_halfwidth_rad,
               "counting_elevation_halfwidth_rad": volume.elevation_halfwidth_rad,
               "counting_volume_m3": volume.volume_m3})
