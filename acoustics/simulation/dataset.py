"""Assemble a simulation into the data contract of processing.base.dataset (SONAR-netCDF4 flavour)."""
from __future__ import annotations

import datetime as _dt
import json
import platform
import sys

import numpy as np
import xarray as xr

from processing.base.dataset import CONVENTIONS, ELEMENT_GROUP, TRUTH_GROUP, split_complex

from acoustics.frames import cartesian_to_spherical
from acoustics.sonar.calibration import sonar_calibration

__all__ = ["build_tree", "beam_group", "provenance_dataset", "versions", "rays_cast", "CHANNEL"]

#: the one SONAR-netCDF4 channel of a run: the receiver; its elements are the beams
CHANNEL = "abacus-receiver"


def _element_geometry(elements, prefix: str, dim: str) -> dict:
    """``<prefix>_x/_y/_z/_width/_height/_rotation`` of an ElementArray along ``dim``."""
    cols = {"x": (elements.center_m[:, 0], "m"), "y": (elements.center_m[:, 1], "m"),
            "z": (elements.center_m[:, 2], "m"), "width": (elements.width_m, "m"),
            "height": (elements.height_m, "m"), "rotation": (elements.rotation_rad, "rad")}
    return {f"{prefix}_{k}": xr.DataArray(v, dims=dim, attrs={"units": u}) for k, (v, u) in cols.items()}

def versions() -> dict:
    """Versions of everything that shapes the numbers."""
    import numba
    import scipy
    from acoustics import __version__
    return {"abacus": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__, "xarray": xr.__version__,
            "platform": platform.platform()}


def provenance_dataset(scene, seed: int, log, rays_cast: dict | None = None) -> xr.Dataset:
    """/Provenance: resolved scene, its sha256, the seed, versions, stages and their times."""
    names = log.names
    return xr.Dataset(
        {"stage_seconds": xr.DataArray(np.array([log.seconds[k] for k in names]), dims="stage",
                                       attrs={"units": "s", "long_name": "wall time per stage"}),
         "stage_calls": xr.DataArray(np.array([log.calls[k] for k in names]), dims="stage")},
        coords={"stage": np.array(names, dtype=str)},
        attrs={"scene_text": scene.resolved_text(), "scene_sha256": scene.sha256(),
               "scene_file": str(scene.source_path or ""), "seed": int(seed),
               "stages_run": ",".join(names), "versions": json.dumps(versions()),
               "rays_cast_json": json.dumps(rays_cast or {}),
               "command": " ".join(sys.argv)})


def _ping_times(scene, pings):
    start = np.datetime64(scene.pings.start_time, "ns")
    step = np.timedelta64(int(round(scene.pings.interval_s * 1e9)), "ns")
    return start + np.asarray(pings, np.int64) * step


def build_tree(scene, setup, pings, samples, clipped, truth, log, seed) -> xr.DataTree:
    """The DataTree of one simulation run (see processing.base.dataset for the layout)."""
    sonar, medium, pulse = setup.sonar, setup.medium, setup.pulse
    s = scene.sampling
    ping_time = _ping_times(scene, pings)
    rx = sonar.receiver
    el = rx.elements
    chan_names = np.array([f"{sub}{idx}" for sub, idx in rx.channels])
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()

    model = "ABACUS" if scene.sonar.preset == "abacus" else "custom"
    root = xr.Dataset(attrs={
        # SONAR-netCDF4 1.0 (ICES CRR 341) top level; echopype reads ``keywords`` as the sonar model
        "conventions": CONVENTIONS, "sonar_convention_authority": "ICES",
        "sonar_convention_name": "SONAR-netCDF4", "sonar_convention_version": "1.0",
        "keywords": model,
        "title": f"abacus simulation: {scene.name}", "summary": scene.description.strip() or scene.name,
        "date_created": now, "software_name": "abacus",
        "software_version": versions()["abacus"], "data_kind": "simulated"})

    env = xr.Dataset({
        "sound_speed_indicative": xr.DataArray(medium.sound_speed_m_s, attrs={"units": "m/s"}),
        "absorption_indicative": xr.DataArray([medium.absorption_db_per_m], dims="frequency",
                                              attrs={"units": "dB/m", "long_name": "indicative absorption "
                                                     "at the transmit centre frequency"}),
        "temperature": xr.DataArray(medium.temperature_c, attrs={"units": "degree_Celsius"}),
        "salinity": xr.DataArray(medium.salinity_psu, attrs={"units": "PSU"}),
        "depth": xr.DataArray(medium.depth_m, attrs={"units": "m", "long_name": "depth at which absorption was evaluated"}),
        "ph": xr.DataArray(medium.ph)},
        coords={"frequency": xr.DataArray([pulse.center_frequency_hz], dims="frequency", attrs={"units": "Hz"})})

    pose = sonar.pose
    platform_ds = xr.Dataset({
        "sonar_position": xr.DataArray(pose.position_m, dims="world_axis",
                                       attrs={"units": "m", "long_name": "sonar-frame origin in the world frame (x forward, y starboard, z down)"}),
        "sonar_rotation": xr.DataArray(pose.rotation, dims=("world_axis", "sonar_axis"),
                                       attrs={"long_name": "columns: sonar axes x_s, y_s, z_s in world coordinates"})},
        coords={"world_axis": ["x", "y", "z"], "sonar_axis": ["x", "y", "z"]})
    for k, a in enumerate("xyz"):   # SONAR-netCDF4's transducer offset: the sonar at rest
        platform_ds[f"transducer_offset_{a}"] = xr.DataArray(
            [pose.position_m[k]], dims="channel", coords={"channel": [CHANNEL]},
            attrs={"units": "m", "long_name": f"transducer {a} offset from the platform origin"})
    if setup.platform is not None:
        # a moving platform: the pose of every ping, and the attitude it came from
        poses = [setup.pose_at(p) for p in pings]
        roll, pitch, yaw, heave = setup.platform.attitude(np.asarray(pings, float) * setup.interval_s)
        platform_ds["ping_sonar_position"] = xr.DataArray(
            np.stack([q.position_m for q in poses]), dims=("ping_time", "world_axis"),
            attrs={"units": "m", "long_name": "sonar-frame origin in the world frame, per ping"})
        platform_ds["ping_sonar_rotation"] = xr.DataArray(
            np.stack([q.rotation for q in poses]), dims=("ping_time", "world_axis", "sonar_axis"),
            attrs={"long_name": "columns: sonar axes in world coordinates, per ping"})
        for name, v, units in (("roll", roll, "arc_degree"), ("pitch", pitch, "arc_degree"),
                               ("heading", yaw, "arc_degree"), ("vertical_offset", heave, "m")):
            vv = np.degrees(v) if units == "arc_degree" else np.asarray(v, float)
            platform_ds[name] = xr.DataArray(np.broadcast_to(vv, (len(pings),)).copy(), dims="ping_time",
                                             attrs={"units": units, "long_name": {
                                                 "roll": "roll, starboard down positive",
                                                 "pitch": "pitch, bow up positive",
                                                 "heading": "yaw (heading change), clockwise from above positive",
                                                 "vertical_offset": "heave, positive up"}[name]})
        platform_ds = platform_ds.assign_coords(ping_time=_ping_times(scene, pings))
        platform_ds.attrs["mount"] = ("sonar_position/sonar_rotation: the mounting pose at rest; "
                                      "ping_sonar_*: the pose of each ping")

    tx = sonar.transmitter
    replica = pulse.replica(s.rate_hz)
    cal_gain, cal_az, cal_width = sonar_calibration(
        tx, sonar.receiver.elements, wavenumber_rad_m=setup.model.wavenumber_rad_m,
        scale_counts=setup.model.scale_counts)
    sonar_ds = xr.Dataset(
        {"transmit_frequency_start": xr.DataArray(pulse.center_frequency_hz - np.sign(pulse.chirp_rate_hz_s or 1) * pulse.bandwidth_hz / 2, attrs={"units": "Hz"}),
         "transmit_frequency_stop": xr.DataArray(pulse.center_frequency_hz + np.sign(pulse.chirp_rate_hz_s or 1) * pulse.bandwidth_hz / 2, attrs={"units": "Hz"}),
         "transmit_frequency_center": xr.DataArray(pulse.center_frequency_hz, attrs={"units": "Hz"}),
         "transmit_bandwidth": xr.DataArray(pulse.bandwidth_hz, attrs={"units": "Hz"}),
         "transmit_duration_nominal": xr.DataArray(pulse.duration_s, attrs={"units": "s"}),
         "beamwidth_transmit_major": xr.DataArray(np.degrees(setup.tx_beamwidth_az_rad),
                                                  attrs={"units": "arc_degree", "long_name": "transmit 3 dB beamwidth in azimuth (sonar x-z plane)"}),
         "beamwidth_transmit_minor": xr.DataArray(np.degrees(setup.tx_beamwidth_el_rad),
                                                  attrs={"units": "arc_degree", "long_name": "transmit 3 dB beamwidth in elevation"}),
         **split_complex("replica", replica, ("replica_sample",),
                         {"long_name": "transmit pulse u(j/fs), complex baseband", "units": "1"}),
         **_element_geometry(tx, "tx_element", "tx_element"),
         "tx_element_weight": xr.DataArray(tx.weight, dims="tx_element"),
         "calibration_gain": xr.DataArray(cal_gain, attrs={
             "units": "counts m", "long_name": "G = k S: image peak of a target of backscatter "
             "amplitude 1 m at 1 m on the transmit axis (see acoustics/calibration.py)"}),
         "beam_group_name": xr.DataArray(["Beam_group1"], dims="beam_group"),
         "beam_group_descr": xr.DataArray(
             ["complex baseband samples of every receive element: one beam per element "
              "(docs/dataset.md, 'Beams are elements')"], dims="beam_group"),
         "two_way_elevation_width": xr.DataArray(cal_width, dims="calibration_azimuth", attrs={
             "units": "rad", "long_name": "integral over elevation of |E_t|^2 |D_rx|^2 cos(elevation), "
             "per azimuth: the sonar's part of echo integration's equivalent beam"})},
        coords={"channel_all": [CHANNEL], "beam_group": ["Beam_group1"], "replica_sample": np.arange(replica.size),
                "calibration_azimuth": xr.DataArray(cal_az, dims="calibration_azimuth",
                                                    attrs={"units": "rad"})},
        attrs={"transmit_type": "LFM", "taper": pulse.taper, "sweep": pulse.sweep,
               "sonar_manufacturer": "abacus (simulated)", "sonar_model": model,
               "sonar_serial_number": "", "sonar_software_name": "abacus",
               "sonar_software_version": versions()["abacus"], "sonar_type": "multibeam",
               "variant": scene.sonar.variant if scene.sonar.preset == "abacus" else "explicit",
               "mode": rx.mode, "frame": "sonar frame: +z boresight, +x along the receiver, +y along the transmitter"})

    eg = beam_group(scene, setup, pings, ping_time, samples, clipped, chan_names,
                    psi_element_sr=float(np.trapezoid(cal_width, cal_az)))

    truth_ds = _truth(setup, pings, ping_time, truth)
    tree = xr.DataTree.from_dict({
        "/": root, "/Environment": env, "/Platform": platform_ds,
        "/Provenance": provenance_dataset(scene, seed, log, rays_cast(setup)), "/Sonar": sonar_ds,
        f"/{ELEMENT_GROUP}": eg, f"/{TRUTH_GROUP}": truth_ds})
    return tree


def _element_beamwidth_deg(size_m, wavelength_m):
    """3 dB full width (deg) of a baffled rectangular piston of this size: |sinc(w u/λ)| = 1/√2
    at w u/λ = 0.4429."""
    return np.degrees(2 * np.arcsin(np.minimum(0.4429 * wavelength_m / np.asarray(size_m, float), 1.0)))


def beam_group(scene, setup, pings, ping_time, samples, clipped, chan_names, *, psi_element_sr):
    """/Sonar/Beam_group1: the per-element samples as SONAR-netCDF4 lays out complex data in
    echopype (``backscatter_r/_i`` on (channel, ping_time, range_sample, beam)), one channel (the
    receiver) whose beams are its elements, with the beam-group variables of the convention and
    the element geometry processing needs."""
    sonar, pulse = setup.sonar, setup.pulse
    s = scene.sampling
    rx = sonar.receiver
    el = rx.elements
    n_p = len(pings)
    lam = setup.medium.sound_speed_m_s / pulse.center_frequency_hz
    rot = sonar.pose.rotation
    # each element faces the sonar's +z (rotations are about z): its direction in the platform frame
    direction = np.broadcast_to(rot @ np.array([0.0, 0.0, 1.0]), (el.n_elements, 3))
    per_ping = lambda v: xr.DataArray(np.full((1, n_p), float(v)), dims=("channel", "ping_time"))
    per_beam = lambda v: xr.DataArray(np.asarray(v, float)[None, :], dims=("channel", "beam"))
    # the samples are already float32 (ping_time, range_sample, beam) planes: wrapped, not copied,
    # and written as they are (a transposed view would be copied whole by the writer)
    attrs = {"units": "ADC counts", "long_name": "complex baseband samples per receive element"}
    pair = {f"backscatter_{k}": xr.DataArray(v[None], dims=("channel", "ping_time", "range_sample", "beam"),
                                             attrs=dict(attrs))
            for k, v in zip("ri", samples)}
    start = pulse.center_frequency_hz - np.sign(pulse.chirp_rate_hz_s or 1) * pulse.bandwidth_hz / 2
    stop = pulse.center_frequency_hz + np.sign(pulse.chirp_rate_hz_s or 1) * pulse.bandwidth_hz / 2
    eg = xr.Dataset(
        {**pair,
         "beam_type": xr.DataArray(["single"], dims="channel",
                                   attrs={"long_name": "each beam is one element's own (unsteered) beam"}),
         "beam_direction_x": per_beam(direction[:, 0]), "beam_direction_y": per_beam(direction[:, 1]),
         "beam_direction_z": per_beam(direction[:, 2]),
         "beamwidth_receive_major": per_beam(_element_beamwidth_deg(el.width_m, lam)),
         "beamwidth_receive_minor": per_beam(_element_beamwidth_deg(el.height_m, lam)),
         "beamwidth_transmit_major": per_beam(np.full(el.n_elements, np.degrees(setup.tx_beamwidth_az_rad))),
         "beamwidth_transmit_minor": per_beam(np.full(el.n_elements, np.degrees(setup.tx_beamwidth_el_rad))),
         "equivalent_beam_angle": per_beam(np.full(el.n_elements, 10 * np.log10(psi_element_sr))),
         "sample_interval": per_ping(1.0 / s.rate_hz),
         "blanking_interval": per_ping(s.time_offset_s),
         "sample_time_offset": per_ping(0.0),
         "transmit_frequency_start": per_ping(start), "transmit_frequency_stop": per_ping(stop),
         "transmit_duration_nominal": per_ping(pulse.duration_s),
         "transmit_bandwidth": per_ping(pulse.bandwidth_hz),
         "transmit_type": xr.DataArray(["LFM"], dims="channel"),
         "beam_stabilisation": xr.DataArray(np.zeros(n_p, np.int8), dims="ping_time"),
         "non_quantitative_processing": xr.DataArray(np.zeros(n_p, np.int16), dims="ping_time"),
         **_element_geometry(el, "element", "beam"),
         "element_subarray": xr.DataArray(rx.channel_subarray.astype(str), dims="beam"),
         "element_index_in_subarray": xr.DataArray(np.array([i for _, i in rx.channels]), dims="beam")},
        coords={"channel": [CHANNEL], "ping_time": ping_time,
                "ping_index": ("ping_time", np.asarray(pings, np.int64)),
                "range_sample": np.arange(s.samples), "beam": chan_names},
        attrs={"mode": rx.mode, "adc_scale_counts": s.adc.scale_counts,
               "adc_quantized": int(s.adc.quantize), "adc_bits": s.adc.bits,
               "noise_enabled": int(scene.noise.enabled), "noise_sigma_counts": scene.noise.sigma_counts,
               "noise_bandwidth_hz": scene.noise.bandwidth_hz,
               "receiver_bandwidth_hz": s.receiver_bandwidth_hz, "beam_mode": "vertical",
               "conversion_equation_type": "none: samples are complex baseband in ADC counts"})
    units = {"beam_direction_x": "1", "beam_direction_y": "1", "beam_direction_z": "1",
             "beamwidth_receive_major": "arc_degree", "beamwidth_receive_minor": "arc_degree",
             "beamwidth_transmit_major": "arc_degree", "beamwidth_transmit_minor": "arc_degree",
             "equivalent_beam_angle": "dB re 1 sr", "sample_interval": "s", "blanking_interval": "s",
             "sample_time_offset": "s", "transmit_frequency_start": "Hz", "transmit_frequency_stop": "Hz",
             "transmit_duration_nominal": "s", "transmit_bandwidth": "Hz"}
    for k, u in units.items():
        eg[k].attrs["units"] = u
    eg["blanking_interval"].attrs["long_name"] = "time of sample 0 after the start of transmission"
    eg["equivalent_beam_angle"].attrs["long_name"] = ("10 log10 of the two-way equivalent solid angle "
                                                      "of the transmitter and one element")
    eg["beam_direction_x"].attrs["long_name"] = "beam (element normal) direction in the platform frame"
    if clipped is not None:
        eg["adc_clipped_samples"] = xr.DataArray(clipped, dims=("ping_time", "beam"),
                                                 attrs={"long_name": "samples clipped by the ADC (I or Q)"})
    return eg


def rays_cast(setup) -> dict:
    """Rays cast per purpose in a run (empty without meshes)."""
    rs = setup.ray_scene
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
    per_ping_in = np.array([int(v.sum()) for v in np.split(inside, np.cumsum(n)[:-1])]) if truth else np.zeros(0, int)
    ds = xr.Dataset(
        {"target_ping_index": xr.DataArray(ping_of, dims="target"),
         "target_x": xr.DataArray(ps[:, 0], dims="target", attrs={"units": "m", "frame": "sonar"}),
         "target_y": xr.DataArray(ps[:, 1], dims="target", attrs={"units": "m", "frame": "sonar"}),
         "target_z": xr.DataArray(ps[:, 2], dims="target", attrs={"units": "m", "frame": "sonar"}),
         "target_world_x": xr.DataArray(pw[:, 0], dims="target", attrs={"units": "m", "frame": "world"}),
         "target_world_y": xr.DataArray(pw[:, 1], dims="target", attrs={"units": "m", "frame": "world"}),
         "target_world_z": xr.DataArray(pw[:, 2], dims="target", attrs={"units": "m", "frame": "world (depth)"}),
         "target_range": xr.DataArray(r, dims="target", attrs={"units": "m"}),
         "target_azimuth": xr.DataArray(az, dims="target", attrs={"units": "rad"}),
         "target_elevation": xr.DataArray(el, dims="target", attrs={"units": "rad"}),
         "target_backscatter_amplitude": xr.DataArray(rho, dims="target", attrs={"units": "m", "long_name": "rho = sqrt(sigma_bs)"}),
         "target_ts": xr.DataArray(ts, dims="target", attrs={"units": "dB re 1 m^2", "long_name": "-inf where rho = 0",
                                                                "nan_means": "-inf: rho = 0 (no echo)"}),
         "target_phase": xr.DataArray(ph, dims="target", attrs={"units": "rad"}),
         "target_group": xr.DataArray(grp, dims="target", attrs={"long_name": "-1 explicit point, else population index"}),
         "target_id": xr.DataArray(tid.astype(np.int64), dims="target", attrs={
             "long_name": "identity: point i is i, fish k of population j is (j + 1) x 1e6 + k; "
                          "persistent across pings for points and populations with redraw: false"}),
         "target_velocity_world_x": xr.DataArray(vel[:, 0], dims="target", attrs={"units": "m/s", "frame": "world"}),
         "target_velocity_world_y": xr.DataArray(vel[:, 1], dims="target", attrs={"units": "m/s", "frame": "world"}),
         "target_velocity_world_z": xr.DataArray(vel[:, 2], dims="target", attrs={"units": "m/s", "frame": "world (depth rate)"}),
         "target_in_counting_volume": xr.DataArray(inside.astype(np.int8), dims="target"),
         "target_shadowed": xr.DataArray(shd.astype(np.int8), dims="target",
                                         attrs={"long_name": "1 where a mesh blocks the direct path (no direct echo)"}),
         "truth_count_total": xr.DataArray(np.asarray(n, np.int64), dims="ping_time"),
         "truth_count_in_volume": xr.DataArray(per_ping_in.astype(np.int64), dims="ping_time")},
        coords={"ping_time": ping_time},
        attrs={"counting_volume": "transmitter 3 dB beam (azimuth, elevation) x image range limits",
               "counting_range_m": list(volume.range_m),
               "counting_azimuth_halfwidth_rad": volume.azimuth_halfwidth_rad,
               "counting_elevation_halfwidth_rad": volume.elevation_halfwidth_rad,
               "counting_volume_m3": volume.volume_m3})
    return ds
