"""SONAR-netCDF4 2.0 files: written from a dataset of the 1.0 contract, read back into one.

The layout is the table of :mod:`processing.base.contract_v2` (docs/dataset.md, "SONAR-netCDF4
2.0"); netCDF4-python writes it, because the convention's variable-length vectors (``sample_t``:
one vector of samples per ping, beam and sub-beam) and enumerations are beyond xarray.

* :func:`write_sonar_netcdf2`: the file of a dataset (:mod:`processing.base.dataset`'s 1.0 tree),
  with a ``SingleTarget`` sub-group from a table of single targets and a gridded group from an
  MVBS grid (/Processing/Sv) when given; atomic, as every writer of abacus.
* :func:`check_file`: where a file departs from the table.
* :func:`read_sonar_netcdf2`: a 2.0 file (abacus' own, or a foreign one such as EK80 writes:
  complex samples of a split-aperture beam's sub-beams) as a 1.0 tree processing reads; every
  pings, every sample (ragged pings padded with zeros to the longest), the whole range. What is
  missing is named in ONE message listing all of it.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Mapping

import numpy as np
import xarray as xr

from processing.base.atomic import staged
from processing.base.contract import (CHANNEL, ELEMENT_GROUP, ENVIRONMENT_GROUP, PLATFORM_GROUP,
                                      PROVENANCE_GROUP, SONAR_GROUP, TRUTH_GROUP)
from processing.base.contract_v2 import (BEAM_GROUP_V2, BEAM_TYPE_ELEMENT_ARRAY, GRID_GROUP,
                                         GROUPS_V2, SINGLE_TARGET_GROUP, TIME_UNITS, VENDOR, NcGroup,
                                         group_v2)
from processing.base.dataset import DatasetError, beam_samples

__all__ = ["write_sonar_netcdf2", "check_file", "is_sonar_netcdf2",
           "TARGET_COLUMNS", "TARGET_PARAMETERS", "SonarNetcdf2Error"]

#: the single-target table's columns: name -> (required, meaning)
TARGET_COLUMNS = {
    "ping": (True, "ping row of each target (0 … n_pings − 1)"),
    "range_m": (True, "range (m)"),
    "azimuth_deg": (True, "azimuth: angle in the sonar x-z plane (deg)"),
    "elevation_deg": (True, "elevation: angle in the sonar y-z plane (deg)"),
    "ts_uncomp_db": (True, "TS uncompensated (dB re 1 m²)"),
    "ts_comp_db": (True, "TS compensated for the beam pattern (dB re 1 m²)"),
    "x_m": (False, "position, sonar frame (m)"), "y_m": (False, ""), "z_m": (False, ""),
    "track_id": (False, "track of the target (negative: none)"),
}
#: detection parameter (SingleTarget ``param_*``) <- key of the parameters given
TARGET_PARAMETERS = {
    "param_TS_threshold": "ts_threshold_db",
    "param_gain_compensation": "max_gain_compensation_db",
    "param_minimum_echo_duration": "min_echo_length",
    "param_maximum_echo_duration": "max_echo_length",
    "param_maximum_phase_deviation": "max_phase_deviation_deg",
    "param_minimum_echo_spacing": "min_echo_spacing",
    "param_TSf_processing_window_duration": "tsf_window_s",
}

_NC_SCALARS = {"float": np.float32, "double": np.float64, "int": np.int32, "short": np.int16,
               "byte": np.int8, "uint64": np.uint64}


class SonarNetcdf2Error(DatasetError):
    """A value or file that does not fit the 2.0 table (named in the message)."""


# ------------------------------------------------------------------ geometry
def _euler_zyx_deg(rotation) -> np.ndarray:
    """(psi, theta, phi) in degrees of R = Rz(psi) Ry(theta) Rx(phi): the convention's intrinsic
    z-y'-x'' beam rotation (its §"Coordinate systems"); shape (..., 3) for R of (..., 3, 3)."""
    r = np.asarray(rotation, float)
    theta = -np.arcsin(np.clip(r[..., 2, 0], -1.0, 1.0))
    # at theta = ±90° (gimbal lock) psi and phi are not unique: phi = 0 then
    lock = np.abs(r[..., 2, 0]) > 1.0 - 1e-12
    phi = np.where(lock, 0.0, np.arctan2(r[..., 2, 1], r[..., 2, 2]))
    psi = np.where(lock, np.arctan2(-r[..., 0, 1], r[..., 1, 1]), np.arctan2(r[..., 1, 0], r[..., 0, 0]))
    return np.degrees(np.stack([psi, theta, phi], -1))


def _extrinsic_xyz_deg(rotation) -> np.ndarray:
    """(x, y, z) angles in degrees of R = Rz(z) Ry(y) Rx(x): extrinsic rotations about x, then y,
    then z (the convention's transducer_rotation_*), the same angles as :func:`_euler_zyx_deg`
    in the other order."""
    psi, theta, phi = np.moveaxis(_euler_zyx_deg(rotation), -1, 0)
    return np.stack([phi, theta, psi], -1)


def _rot_y(angle_rad) -> np.ndarray:
    """Rotations about y by ``angle_rad`` (shape (n,)) as (n, 3, 3): z turns towards x."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def _proper(rotation, where: str) -> np.ndarray:
    r = np.asarray(rotation, float)
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise SonarNetcdf2Error(f"{where}: the sonar rotation is not a proper rotation (orthonormal, "
                                f"det +1); SONAR-netCDF4 beam rotations cannot express it")
    return r


# ------------------------------------------------------------------ writing one group
def _nc_type(nc, name: str, spec: NcGroup):
    """The netCDF type of a table type name: a numpy dtype, str, or a user type of the group
    or an enclosing one."""
    if name == "string":
        return str
    if name in _NC_SCALARS:
        return np.dtype(_NC_SCALARS[name])
    g = nc
    while g is not None:
        for table in (g.enumtypes, g.vltypes):
            if name in table:
                return table[name]
        g = g.parent
    raise SonarNetcdf2Error(f"{spec.path}: type {name!r} is not defined in the table")


def _make_types(nc, spec: NcGroup) -> None:
    for t in spec.types:
        base = np.dtype(_NC_SCALARS[t.base])
        if t.kind == "enum":
            nc.createEnumType(base, t.name, dict(t.members))
        else:
            nc.createVLType(base, t.name)


def _dims_visible(nc) -> dict:
    out, g = {}, nc
    while g is not None:
        out = {**g.dimensions, **out}
        g = g.parent
    return out


def _write_group(nc, path: str, values: Mapping, attrs: Mapping | None = None, *, unlimited=()) -> None:
    """Write the variables ``values`` (name -> array; object arrays of 1-D arrays for vlen
    types) of the table's group ``path`` into the netCDF4 group ``nc``: types first, then each
    dimension as the first variable using it gives its length, then the variables with the
    table's type, dimensions and attributes; then the group's fixed and given attributes."""
    spec = group_v2(path)
    _make_types(nc, spec)
    for name, value in values.items():
        v = spec.variable(name)
        if v is None:
            raise SonarNetcdf2Error(f"{path}/{name}: not in the SONAR-netCDF4 2.0 table "
                                    f"(processing/base/contract_v2.py)")
        a = np.asarray(value) if not isinstance(value, np.ndarray) else value
        if a.ndim != len(v.dims):
            raise SonarNetcdf2Error(f"{path}/{name}: {a.ndim} dimension(s) given, the table has "
                                    f"{len(v.dims)} ({', '.join(v.dims) or 'a scalar'})")
        have = _dims_visible(nc)
        for d, n in zip(v.dims, a.shape):
            if d not in have:
                nc.createDimension(d, None if (d in unlimited or n == 0) else n)
                have = _dims_visible(nc)
            elif not have[d].isunlimited() and len(have[d]) != n:
                raise SonarNetcdf2Error(f"{path}/{name}: dimension {d} is {len(have[d])} long, "
                                        f"{n} given")
        dtype = _nc_type(nc, v.type, spec)
        fill = {}
        if isinstance(dtype, np.dtype) and dtype.kind == "f":
            fill = {"fill_value": np.array(np.nan, dtype)}
        var = nc.createVariable(name, dtype, v.dims, **fill)
        for k, val in v.attributes().items():
            if isinstance(val, tuple):
                val = np.asarray(val, dtype if isinstance(dtype, np.dtype) and dtype.kind == "f" else float)
            var.setncattr(k, val)
        if v.type == "string":
            flat = np.asarray(a, object).ravel()
            out = np.empty(flat.size, object)
            out[:] = [str(s) for s in flat]
            var[...] = out.reshape(a.shape) if a.ndim else out[0]
        elif isinstance(dtype, np.dtype):
            if a.ndim == 0:
                var.assignValue(a.astype(dtype))
            elif a.size:
                var[...] = a.astype(dtype)
        elif hasattr(dtype, "enum_dict"):
            var[...] = np.asarray(a, dtype.dtype) if a.ndim else np.asarray(a, dtype.dtype).reshape(())
        else:                                              # vlen: one 1-D array per cell
            base = dtype.dtype
            out = np.empty(a.shape, object)
            for idx in np.ndindex(a.shape):
                out[idx] = np.asarray(a[idx], base).ravel()
            if a.size:
                var[...] = out
    fixed = {x.name: x.value for x in spec.attributes if x.value is not None}
    for k, val in {**fixed, **(attrs or {})}.items():
        if spec.attribute(k) is None:
            raise SonarNetcdf2Error(f"{path}: attribute {k!r} is not in the SONAR-netCDF4 2.0 table")
        if val is None:
            continue
        nc.setncattr(k, val)


def _vlen(arrays, shape) -> np.ndarray:
    out = np.empty(shape, object)
    for idx, a in zip(np.ndindex(shape), arrays):
        out[idx] = a
    return out


# ------------------------------------------------------------------ the 1.0 tree's values
def _ds(tree, group) -> xr.Dataset | None:
    try:
        return tree[group].to_dataset(inherit=False)
    except KeyError:
        return None


def _get(ds, name, default=None):
    if ds is None or name not in ds.variables:
        return default
    return np.asarray(ds[name].values)


def _first(ds, name, default=np.nan) -> float:
    v = _get(ds, name)
    return float(np.ravel(v)[0]) if v is not None and np.size(v) else float(default)


def _per_ping(ds, name, n_p, default=np.nan) -> np.ndarray:
    """A (channel, ping_time), (ping_time,) or scalar variable as (n_p,) floats."""
    v = _get(ds, name)
    if v is None:
        return np.full(n_p, float(default))
    v = np.asarray(v, float)
    if v.ndim == 2:                                   # (channel, ping_time): the one channel
        return v[0]
    return np.broadcast_to(v.ravel()[0] if v.size == 1 else v, (n_p,)).astype(float)


def _ns(times) -> np.ndarray:
    """Times as the convention's uint64 nanoseconds since 1970 (:data:`TIME_UNITS`)."""
    t = np.asarray(times)
    ns = t.astype("datetime64[ns]").astype(np.int64) if np.issubdtype(t.dtype, np.datetime64) \
        else np.asarray(t, np.int64)
    if ns.size and ns.min() < 0:      # uint64 would wrap them round to the 26th century
        raise SonarNetcdf2Error(f"ping times before 1970 ({np.datetime64(int(ns.min()), 'ns')}) cannot be "
                                f"written as {TIME_UNITS}")
    return ns.astype(np.uint64)


def write_sonar_netcdf2(tree: xr.DataTree, path, *, targets: Mapping | None = None,
                        target_parameters: Mapping | None = None, grid: xr.Dataset | None = None,
                        command: str = "") -> Path:
    """Write a dataset as SONAR-netCDF4 2.0 (atomically).

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset of the 1.0 contract (simulated, converted or processed).
    path : str or Path
        The ``.nc`` file to write.
    targets : mapping of str to array_like, shape (n_targets,) each, optional
        The single targets (:data:`TARGET_COLUMNS`): they fill /Sonar/Beam_group1/SingleTarget.
    target_parameters : mapping, optional
        The detection's parameters by the keys of :data:`TARGET_PARAMETERS` (the ``param_*``
        variables; NaN for a criterion not applied).
    grid : xarray.Dataset, optional
        An MVBS grid as :func:`processing.sv` writes it to /Processing/Sv: fills
        /Sonar/Grid_group1.
    command : str
        The command line, for /Provenance's history.

    Returns
    -------
    Path

    Raises
    ------
    SonarNetcdf2Error
        A dataset the table cannot hold (named).
    """
    import netCDF4
    path = Path(path)
    values = _file_values(tree, targets, target_parameters, grid, command)
    with staged(path) as tmp:
        with netCDF4.Dataset(tmp, "w", format="NETCDF4") as nc:
            for gpath, (vals, attrs) in values.items():
                if gpath == VENDOR:
                    _write_truth(nc.createGroup(VENDOR.strip("/")), vals)
                    continue
                grp = nc if gpath == "/" else nc.createGroup(gpath.strip("/")) if gpath.count("/") == 1 \
                    else nc[str(Path(gpath).parent)].createGroup(Path(gpath).name)
                _write_group(grp, gpath, vals, attrs, unlimited=("ping_time",))
    return path


def _write_truth(nc, ds: xr.Dataset) -> None:
    """abacus' ground truth, the 1.0 /Vendor_specific group as it is (times as ns since 1970)."""
    for name, var in ds.variables.items():
        for d, n in zip(var.dims, var.shape):
            if d not in nc.dimensions:
                nc.createDimension(d, n)
        a = np.asarray(var.values)
        attrs = {k: v for k, v in var.attrs.items() if k != "_FillValue"}
        if np.issubdtype(a.dtype, np.datetime64):
            a, attrs["units"] = _ns(a), TIME_UNITS
        if a.dtype.kind in "USO":
            v = nc.createVariable(str(name), str, var.dims)
            flat = np.empty(a.size, object)
            flat[:] = [str(s) for s in a.ravel()]
            v[...] = flat.reshape(a.shape)
        else:
            if a.dtype == bool:
                a = a.astype(np.int8)
            v = nc.createVariable(str(name), a.dtype, var.dims)
            if a.size:
                v[...] = a
        for k, val in attrs.items():
            v.setncattr(k, val if not isinstance(val, (list, tuple)) else np.asarray(val))
    for k, val in ds.attrs.items():
        nc.setncattr(k, val if not isinstance(val, (list, tuple)) else np.asarray(val))


def _file_values(tree, targets, parameters, grid, command) -> dict:
    """Group path -> (values, attributes) of the whole file."""
    where = tree.attrs.get("title", "dataset")
    beam = _ds(tree, ELEMENT_GROUP)
    sonar = _ds(tree, SONAR_GROUP)
    env = _ds(tree, ENVIRONMENT_GROUP)
    plat = _ds(tree, PLATFORM_GROUP)
    if beam is None or sonar is None or env is None:
        raise SonarNetcdf2Error(f"{where}: a dataset needs /Sonar, /Sonar/Beam_group1 and /Environment "
                                f"to be written as SONAR-netCDF4 2.0")
    x = np.asarray(beam_samples(beam, where=where))          # (ping, element, sample) complex64
    n_p, n_e, n_s = x.shape
    times = _ns(beam["ping_time"].values)
    f0 = _first(sonar, "transmit_frequency_center")
    c = _first(env, "sound_speed_indicative")
    rot = _proper(_get(plat, "sonar_rotation", np.eye(3)), where)
    origin = np.asarray(_get(plat, "sonar_position", np.zeros(3)), float)
    ones = np.ones((n_p, 1))
    rx_euler = _euler_zyx_deg(rot)
    boresight = rot @ np.array([0.0, 0.0, 1.0])
    interval = _per_ping(beam, "sample_interval", n_p)
    f_start = _per_ping(beam, "transmit_frequency_start", n_p, _first(sonar, "transmit_frequency_start",
                                                                      f0 - _first(sonar, "transmit_bandwidth") / 2))
    f_stop = _per_ping(beam, "transmit_frequency_stop", n_p, _first(sonar, "transmit_frequency_stop",
                                                                    f0 + _first(sonar, "transmit_bandwidth") / 2))
    replica = _get(sonar, "replica_r").astype(np.float32) + 1j * _get(sonar, "replica_i").astype(np.float32)
    duration = _per_ping(beam, "transmit_duration_nominal", n_p,
                         _first(sonar, "transmit_duration_nominal", replica.size * interval[0]))
    eba_db = _get(beam, "equivalent_beam_angle")
    widths = {a: _get(beam, f"beamwidth_receive_{a}") for a in ("major", "minor")}
    sub = np.asarray(_get(beam, "element_subarray")).astype(str)
    pos = np.stack([np.asarray(_get(beam, f"element_{a}"), float) for a in "xyz"], -1)
    txpos = np.stack([np.asarray(_get(sonar, f"tx_element_{a}"), float) for a in "xyz"], -1)
    txw = np.asarray(_get(sonar, "tx_element_weight", np.ones(len(txpos))), float)

    def scalar_or_nan(a):
        return np.nan if a is None else float(np.nanmean(np.asarray(a, float)))

    bvals = {
        "beam": np.array([CHANNEL]), "ping_time": times, "frequency": [f0], "calibrated_frequency": [f0],
        "backscatter_r": _vlen((x[p, e].real for p in range(n_p) for e in range(n_e)), (n_p, 1, n_e)),
        "backscatter_i": _vlen((x[p, e].imag for p in range(n_p) for e in range(n_e)), (n_p, 1, n_e)),
        "sample_count": np.full((n_p, 1, n_e), n_s),
        "beam_type": np.int8(BEAM_TYPE_ELEMENT_ARRAY),
        "beam_stabilisation": np.zeros(n_p, np.int8), "non_quantitative_processing": np.zeros(n_p, np.int16),
        "beamwidth_receive_major": ones * scalar_or_nan(widths["major"]),
        "beamwidth_receive_minor": ones * scalar_or_nan(widths["minor"]),
        "equivalent_beam_angle": ones * (np.nan if eba_db is None else float(np.mean(10 ** (np.asarray(eba_db) / 10)))),
        **{f"rx_beam_rotation_{k}": ones * rx_euler[i] for i, k in enumerate(("psi", "theta", "phi"))},
        **{f"tx_beam_rotation_{k}": ones * rx_euler[i] for i, k in enumerate(("psi", "theta", "phi"))},
        "sample_interval": interval,
        "blanking_interval": _per_ping(beam, "blanking_interval", n_p, 0.0)[:, None],
        "sample_time_offset": _per_ping(beam, "sample_time_offset", n_p, 0.0)[:, None],
        "transmit_duration_nominal": duration[:, None],
        "transmit_frequency_start": f_start[:, None], "transmit_frequency_stop": f_stop[:, None],
        "transmit_bandwidth": _per_ping(beam, "transmit_bandwidth", n_p, _first(sonar, "transmit_bandwidth"))[:, None],
        "transmit_type": np.where(np.isclose(f_start, f_stop), 0, 1).astype(np.int8)[:, None],
        "beamwidth_transmit_major": ones * _first(sonar, "beamwidth_transmit_major"),
        "beamwidth_transmit_minor": ones * _first(sonar, "beamwidth_transmit_minor"),
        "transmit_pulse_model_r": _vlen([replica.real] * n_p, (n_p, 1)),
        "transmit_pulse_model_i": _vlen([replica.imag] * n_p, (n_p, 1)),
        "receive_transducer_index": [1], "transmit_transducer_index": np.zeros((n_p, 1), int),
        "transmit_beam_index": np.zeros((n_p, 1), int),
        "platform_latitude": np.full(n_p, np.nan), "platform_longitude": np.full(n_p, np.nan),
        "platform_heading": np.mod(_per_ping(plat, "heading", n_p, 0.0), 360.0),
        "platform_pitch": _per_ping(plat, "pitch", n_p, 0.0), "platform_roll": _per_ping(plat, "roll", n_p, 0.0),
        "platform_vertical_offset": _per_ping(plat, "vertical_offset", n_p, 0.0),
        "sound_speed_at_transducer": np.full(n_p, c),
        "ping_index": _get(beam, "ping_index", np.arange(n_p)),
        **{f"beam_direction_{a}": [boresight[i]] for i, a in enumerate("xyz")},
        **{f"tx_beam_direction_{a}": [boresight[i]] for i, a in enumerate("xyz")},
        "subbeam": np.asarray(beam["beam"].values).astype(str), "subbeam_subarray": sub,
        "subbeam_index_in_subarray": _get(beam, "element_index_in_subarray", np.zeros(n_e, int)),
        **{f"subbeam_{a}": pos[:, i] for i, a in enumerate("xyz")},
    }
    for a in ("width", "height", "rotation"):
        if f"element_{a}" in beam.variables:
            bvals[f"subbeam_{a}"] = _get(beam, f"element_{a}")
    if "adc_clipped_samples" in beam.variables:
        bvals["adc_clipped_samples"] = _get(beam, "adc_clipped_samples")
    battrs = {k: v for k, v in beam.attrs.items() if k in ("mode", "adc_scale_counts", "adc_quantized",
                                                           "adc_bits", "noise_enabled", "noise_sigma_counts",
                                                           "noise_bandwidth_hz", "receiver_bandwidth_hz")}
    battrs["conversion_equation_type"] = np.int8(4)

    alpha = _get(env, "absorption_indicative")
    freq = _get(env, "frequency")
    env_vals = {"sound_speed_indicative": c,
                **{k: _first(env, k) for k in ("temperature", "salinity", "depth", "ph") if k in env.variables}}
    if alpha is not None:
        alpha = np.atleast_1d(np.asarray(alpha, float))
        env_vals.update(absorption_indicative=alpha,
                        frequency=np.atleast_1d(freq) if freq is not None else np.full(alpha.size, f0))
    else:        # mandatory in 2.0: a recording that does not say it holds the fill value, NaN
        env_vals.update(absorption_indicative=[np.nan], frequency=[f0])

    tx_centre = (txpos * np.abs(txw)[:, None]).sum(0) / np.abs(txw).sum()
    offsets = np.stack([origin + rot @ tx_centre, origin + rot @ pos.mean(0)])
    ext = _extrinsic_xyz_deg(rot)
    pvals = {"transducer_ids": np.array(["abacus-transmitter", CHANNEL]),
             "transducer_function": np.array([1, 0], np.int8),
             **{f"transducer_offset_{a}": offsets[:, i] for i, a in enumerate("xyz")},
             **{f"transducer_rotation_{a}": np.full(2, ext[i]) for i, a in enumerate("xyz")},
             "position_ids": np.array([], str), "MRU_ids": np.array([], str),
             "sonar_position": origin, "sonar_rotation": rot}
    if plat is not None and "ping_sonar_rotation" in plat.variables:
        pvals.update(ping_sonar_position=_get(plat, "ping_sonar_position"),
                     ping_sonar_rotation=_get(plat, "ping_sonar_rotation"), ping_time=_ns(plat["ping_time"].values))

    svals = {"transmit_frequency_center": f0,
             **{f"tx_element_{a}": txpos[:, i] for i, a in enumerate("xyz")}, "tx_element_weight": txw}
    for name in ("calibration_gain", "two_way_elevation_width", "calibration_azimuth", "tx_element_width",
                 "tx_element_height", "tx_element_rotation"):
        if name in sonar.variables:
            svals[name] = _get(sonar, name)
    sattrs = {k: sonar.attrs.get(k, "") for k in ("sonar_manufacturer", "sonar_model", "sonar_serial_number",
                                                  "sonar_software_name", "sonar_software_version")}
    sattrs.update({k: sonar.attrs[k] for k in ("taper", "sweep", "variant", "frame") if k in sonar.attrs})

    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    ra = tree.attrs
    root_attrs = {"date_created": ra.get("date_created", now),
                  "keywords": ", ".join(k for k in (ra.get("keywords", ""), "multibeam sonar") if k),
                  "summary": ra.get("summary", ""), "title": ra.get("title", "")}
    root_attrs.update({k: ra[k] for k in ("data_kind", "software_name", "software_version", "source") if k in ra})
    prov = _ds(tree, PROVENANCE_GROUP)
    version = ra.get("software_version", "")
    source = (prov.attrs.get("scene_file") if prov is not None else None) or ra.get("source") or "(simulated)"
    pattrs = {"conversion_software_name": "abacus", "conversion_software_version": str(version),
              "conversion_time": now,
              "history": f"{now} abacus: SONAR-netCDF4 2.0 from the 1.0 dataset" + (f" ({command})" if command else "")}
    if prov is not None:
        pattrs.update({k: str(prov.attrs[k]) for k in ("scene_sha256", "scene_text", "seed") if k in prov.attrs})

    out = {"/": ({}, root_attrs), "/Environment": (env_vals, None), "/Platform": (pvals, None),
           "/Provenance": ({"source_filenames": np.array([str(source)])}, pattrs),
           "/Sonar": (svals, sattrs), BEAM_GROUP_V2: (bvals, battrs)}
    if targets is not None:
        out[SINGLE_TARGET_GROUP] = (_target_values(targets, parameters, n_p, where), None)
    if grid is not None:
        out[GRID_GROUP] = _grid_values(grid, times, rot, origin, bvals, f0, widths["minor"], where)
    truth = _ds(tree, TRUTH_GROUP)
    if truth is not None:
        out[VENDOR] = (truth, None)
    return out


def _target_values(targets: Mapping, parameters: Mapping | None, n_p: int, where: str) -> dict:
    """The SingleTarget variables of a table of targets: one vector per ping (and the one beam)."""
    missing = [k for k, (req, _) in TARGET_COLUMNS.items() if req and k not in targets]
    if missing:
        raise SonarNetcdf2Error(f"{where}: the single-target table lacks column(s) {', '.join(missing)} "
                                f"(accepted columns: {', '.join(TARGET_COLUMNS)})")
    col = {k: np.asarray(v) for k, v in targets.items() if k in TARGET_COLUMNS}
    ping = col["ping"].astype(int)
    if ping.size and (ping.min() < 0 or ping.max() >= n_p):
        raise SonarNetcdf2Error(f"{where}: single-target ping rows must lie in 0…{n_p - 1}")
    track = col.get("track_id", np.full(ping.size, -1)).astype(np.int64)
    # a target never tracked gets a number of its own, above every track id
    own = np.cumsum(track < 0) - 1 + (int(track.max()) + 1 if track.size and track.max() >= 0 else 0)
    ident = np.where(track >= 0, track, own).astype(np.int32)
    rows = [np.flatnonzero(ping == p) for p in range(n_p)]

    def per_ping(a, dtype=np.float32):
        return _vlen((np.asarray(a)[r].astype(dtype) for r in rows), (n_p, 1))

    vals = {"single_target_count": np.array([[r.size] for r in rows]),
            "single_target_identifier": per_ping(ident, np.int32),
            "single_target_range": per_ping(col["range_m"]),
            "single_target_alongship_angle": per_ping(col["elevation_deg"]),
            "single_target_athwartship_angle": per_ping(col["azimuth_deg"]),
            "compensated_TS": _vlen((col["ts_comp_db"][r].astype(np.float32) for r in rows), (n_p, 1, 1)),
            "uncompensated_TS": _vlen((col["ts_uncomp_db"][r].astype(np.float32) for r in rows), (n_p, 1, 1))}
    for a in "xyz":
        if f"{a}_m" in col:
            vals[f"single_target_{a}"] = per_ping(col[f"{a}_m"])
    given = dict(parameters or {})
    unknown = set(given) - set(TARGET_PARAMETERS.values())
    if unknown:
        raise SonarNetcdf2Error(f"{where}: unknown single-target parameter(s) {', '.join(sorted(unknown))} "
                                f"(accepted: {', '.join(TARGET_PARAMETERS.values())})")
    for var, key in TARGET_PARAMETERS.items():
        v = given.get(key)
        vals[var] = np.full((n_p, 1), np.nan if v is None else float(v))
    return vals


def _grid_values(grid: xr.Dataset, times, rot, origin, beam_vals, f0, minor_width, where) -> tuple:
    """The gridded group's variables and attributes of an MVBS grid (/Processing/Sv)."""
    sv = np.asarray(grid["Sv_mean"].values, float)                  # (ping_bin, range_bin, beam)
    lin = np.asarray(grid["s_v_mean"].values, float) if "s_v_mean" in grid else 10 ** (sv / 10)
    n_pb, n_rb, n_b = sv.shape
    az = np.radians(np.asarray(grid["beam_angle_deg"].values, float))
    first = np.asarray(grid["ping_bin_first_row"].values, int)
    last = np.asarray(grid["ping_bin_last_row"].values, int)
    r0 = np.asarray(grid["range_bin_start_m"].values, float)
    r1 = np.asarray(grid["range_bin_stop_m"].values, float)
    names = np.array([f"fan{b:03d}" for b in range(n_b)])
    beam_rot = rot[None] @ _rot_y(az)                                # beam frame -> platform, per beam
    eul = _euler_zyx_deg(beam_rot)                                   # (n_b, 3)
    tx = _euler_zyx_deg(rot)
    rc = 0.5 * (r0 + r1)
    local = np.stack([rc[:, None] * np.sin(az)[None], np.zeros((n_rb, n_b)), rc[:, None] * np.cos(az)[None]], -1)
    depth = origin[2] + local @ rot[2]                               # world z of each cell centre
    cell_time = np.array([np.mean(times[a:b + 1].astype(np.float64)) for a, b in zip(first, last)])
    one = np.ones((n_pb, 1))
    per_axis = {k: beam_vals[k][first][:, :1] for k in
                ("transmit_duration_nominal", "transmit_frequency_start", "transmit_frequency_stop",
                 "transmit_bandwidth", "transmit_type", "beamwidth_transmit_major",
                 "beamwidth_transmit_minor", "sample_time_offset")}
    vals = {
        "beam": names, "frequency": np.full(n_b, f0), "beam_reference": names,
        "backscatter_type": np.zeros(n_b, np.int8),
        "ping_axis_interval_type": np.int8(3), "ping_axis_interval_value": float(grid.attrs.get("ping_bin", np.nan)),
        "range_axis_interval_type": np.int8(0),
        "range_axis_interval_value": float(grid.attrs.get("range_bin_m", np.nan)),
        "cell_ping_time": np.round(cell_time).astype(np.uint64)[:, None],
        "integrated_backscatter": sv,            # (ping bin, range bin, formed beam = frequency entry)
        "sv_linear": lin,
        "beamwidth_receive_major": np.full((n_pb, n_b), np.nan),
        "beamwidth_receive_minor": np.full((n_pb, n_b), np.nan if minor_width is None
                                           else float(np.nanmean(minor_width))),
        **{f"rx_beam_rotation_{k}": np.broadcast_to(eul[:, i], (n_pb, n_b))
           for i, k in enumerate(("psi", "theta", "phi"))},
        **{f"tx_beam_rotation_{k}": one * tx[i] for i, k in enumerate(("psi", "theta", "phi"))},
        "beam_stabilisation": np.zeros(n_pb, np.int8), "beam_type": np.zeros(n_b, np.int8),
        "equivalent_beam_angle": np.full((n_pb, n_b), np.nan),
        "non_quantitative_processing": np.zeros(n_pb, np.int16),
        "sample_interval": np.broadcast_to(beam_vals["sample_interval"][first][:, None], (n_pb, n_b)),
        "blanking_interval": np.broadcast_to(beam_vals["blanking_interval"][first], (n_pb, n_b)),
        **per_axis,
        "receive_transducer_index": np.ones(n_b, int),
        "cell_latitude": np.full((n_pb, n_rb, n_b), np.nan), "cell_longitude": np.full((n_pb, n_rb, n_b), np.nan),
        "cell_depth": depth, "range_axis_start": r0, "range_axis_stop": r1,
        "ping_axis_first_ping": first, "ping_axis_last_ping": last, "beam_azimuth": np.degrees(az),
    }
    attrs = {"conversion_equation_type": np.int8(4), "noise_sigma_counts": grid.attrs.get("noise_sigma_counts"),
             "image_group": grid.attrs.get("image_group")}
    return vals, attrs


# ------------------------------------------------------------------ checking
def _nc_type_name(var) -> str:
    dt = var.datatype
    if var.dtype is str:
        return "string"
    if hasattr(dt, "name") and not isinstance(dt, np.dtype):
        return dt.name
    for k, v in _NC_SCALARS.items():
        if np.dtype(v) == dt:
            return k
    return str(dt)


def _same_type(var, want: str, grp) -> bool:
    """Whether a variable has the table's type. Variable-length types of one base are told
    apart by their base only: netCDF-C reads a variable of one of several equal vlen types
    (``sample_t``, ``pulse_t``: vectors of float) as the first of them."""
    import netCDF4
    got = _nc_type_name(var)
    if got == want:
        return True
    if isinstance(var.datatype, netCDF4.VLType) and var.dtype is not str:
        g = grp
        while g is not None:
            if want in g.vltypes:
                return g.vltypes[want].dtype == var.datatype.dtype
            g = g.parent
    return False


def check_file(path) -> list:
    """Where a SONAR-netCDF4 2.0 file departs from abacus' 2.0 table, one line each.

    Checked: every variable of a group of the table is in the table, with its type, dimensions
    and units; the table's mandatory (M) variables and attributes of each group written are
    present; /, /Environment, /Platform, /Provenance, /Sonar and /Sonar/Beam_group1 are.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of str
    """
    import netCDF4
    problems = []
    with netCDF4.Dataset(path) as nc:
        for gpath, spec in GROUPS_V2.items():
            try:
                grp = nc if gpath == "/" else nc[gpath]
            except (IndexError, KeyError):
                if gpath not in (SINGLE_TARGET_GROUP, GRID_GROUP):
                    problems.append(f"{gpath}: mandatory group missing")
                continue
            for name, var in grp.variables.items():
                v = spec.variable(name)
                if v is None:
                    problems.append(f"{gpath}/{name}: not in the 2.0 table")
                    continue
                if not _same_type(var, v.type, grp):
                    problems.append(f"{gpath}/{name}: type {_nc_type_name(var)}, the table has {v.type}")
                if tuple(var.dimensions) != v.dims:
                    problems.append(f"{gpath}/{name}: dims {tuple(var.dimensions)}, the table has {v.dims}")
                units = var.getncattr("units") if "units" in var.ncattrs() else None
                if units != v.units:
                    problems.append(f"{gpath}/{name}: units {units!r}, the table has {v.units!r}")
            problems += [f"{gpath}/{v.name}: mandatory, missing" for v in spec.variables
                         if v.obligation == "M" and v.name not in grp.variables]
            problems += [f"{gpath}: mandatory attribute {a.name!r} missing" for a in spec.attributes
                         if a.mandatory and a.name not in grp.ncattrs()]
    return problems


# ------------------------------------------------------------------ reading
def is_sonar_netcdf2(path) -> bool:
    """Whether ``path`` is a netCDF4 file that says it follows SONAR-netCDF4 2.x (its root
    attribute ``sonar_convention_version``); False for anything else, never an error."""
    from processing.base.dataset import sonar_convention_version
    p = Path(path)
    return p.is_file() and sonar_convention_version(p).startswith("2")
