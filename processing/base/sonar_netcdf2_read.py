"""SONAR-netCDF4 2.0 files in: a 2.0 beam group as a dataset of the 1.0 contract.

Two kinds of 2.0 file are read, both completely (every ping, every sample, the whole range):

* abacus' own (:mod:`processing.base.sonar_netcdf2`): its vendor variables give back the element
  geometry, subarrays, calibration, the sonar's pose and the ground truth;
* a foreign one, as an EK80 writes natively: complex samples of each sub-beam of a split-aperture
  beam (``beam_type`` ``split_aperture_4_subbeams``, or ``single``). The four quadrants become four
  elements: their centres are half the phase-centre spacing d from the axis, d = S λ / 2π from the
  angle sensitivity S (``echoangle_major/minor_sensitivity``, electrical degrees per degree: the
  phase k d sin θ of a target θ off axis) — sonar x athwartship (starboard +), sonar y
  alongship (fore +); subarray A the aft pair (sectors 1, 2: aft-starboard, aft-port), B the fore
  pair (3, 4: fore-port, fore-starboard), so A/B interferometry measures the alongship angle and
  beamforming the athwartship one. A monostatic transducer transmits from the origin.

Pings of different lengths (the convention's ragged ``sample_t`` vectors) are padded with zeros
to the longest. Whatever a file lacks that processing needs is named in ONE message listing all
of it. Power/angle samples (``split_aperture_angles``) carry no per-sub-beam phase and are refused
in one line saying so.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.contract import (BEAM_GROUP_NAME, CHANNEL, ELEMENT_GROUP, ENVIRONMENT_GROUP,
                                      PLATFORM_GROUP, PROVENANCE_GROUP, ROOT_GROUP, SONAR_GROUP, TRUTH_GROUP,
                                      group_spec)
from processing.base.dataset import DatasetError, DatasetWarning
from processing.base.groups import build_group, complex_pair, per_beam, per_ping, tree_of

__all__ = ["read_sonar_netcdf2", "SECTOR_LAYOUT"]

#: sub-beam of a four-quadrant split-aperture beam -> (athwartship sign, alongship sign, subarray):
#: EK80's sector order (aft-starboard, aft-port, fore-port, fore-starboard)
SECTOR_LAYOUT = ((+1, -1, "A"), (-1, -1, "A"), (-1, +1, "B"), (+1, +1, "B"))
_EPOCHS = {"1970": np.datetime64("1970-01-01T00:00:00", "ns"), "1601": np.datetime64("1601-01-01T00:00:00", "ns")}


def _var(grp, name):
    return grp.variables[name] if grp is not None and name in grp.variables else None


def _group(nc, path):
    try:
        return nc[path]
    except (IndexError, KeyError):
        return None


def _array(var) -> np.ndarray:
    """A variable's values as a plain array: masked values as NaN (floats), vlen cells kept."""
    a = var[...]
    if np.ma.isMaskedArray(a):
        a = a.filled(np.nan) if a.dtype.kind == "f" else a.data
    return np.asarray(a)


def _one(var, where: str) -> float:
    """The one value of a per-ping (and per-beam) setting; a record holds one setting."""
    v = np.asarray(_array(var), float).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise DatasetError(f"{where}: holds no finite value")
    if np.ptp(v) > 1e-9 * max(abs(v[0]), 1e-30):
        raise DatasetError(f"{where}: changes across pings or beams ({v.min():.6g}…{v.max():.6g}); "
                           f"a record must hold one setting")
    return float(v[0])


def _times(var, where: str) -> np.ndarray:
    units = str(getattr(var, "units", ""))
    if not units.startswith("nanoseconds since "):
        raise DatasetError(f"{where}: units {units!r}; accepted: nanoseconds since 1970-01-01 00:00:00Z "
                           f"or since 1601-01-01 00:00:00Z")
    epoch = _EPOCHS.get(units.split("since ")[1][:4])
    if epoch is None:
        raise DatasetError(f"{where}: epoch of {units!r} is neither 1970 nor 1601")
    ns = np.asarray(_array(var)).astype(np.int64)
    return epoch + ns.astype("timedelta64[ns]")


def _cells(var, shape_prefix) -> np.ndarray:
    """The vlen cells (ping, beam, sub-beam) of a sample variable as an object array."""
    a = _array(var)
    if a.dtype != object:                        # a fixed-length writer: the last axis is samples
        out = np.empty(a.shape[:-1], object)
        for idx in np.ndindex(out.shape):
            out[idx] = a[idx]
        return out
    return a


def read_sonar_netcdf2(path, *, beam_group: str = "Beam_group1",
                       max_memory_gb: float | None = None) -> xr.DataTree:
    """A SONAR-netCDF4 2.0 file as a dataset of the 1.0 contract (what processing reads).

    Parameters
    ----------
    path : str or Path
    beam_group : str
        The beam group of /Sonar to read (one beam, its sub-beams the elements).
    max_memory_gb : float, optional
        The memory limit (default: :func:`processing.base.resources.memory_limit_bytes`): the
        samples, held as vectors and then as one padded complex array, must fit it.

    Returns
    -------
    xarray.DataTree
        /, /Environment, /Sonar, /Sonar/Beam_group1; /Platform and /Vendor_specific where the
        file has abacus' vendor variables. Samples are (channel, ping_time, range_sample, beam)
        float32 pairs; pings shorter than the longest are padded with zeros.

    Raises
    ------
    DatasetError
        Not readable, or lacking what processing needs: ONE message naming every missing
        variable; power/angle samples; more than one beam.
    """
    import netCDF4

    from processing.base.resources import Estimate, check_resources
    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise DatasetError(f"{path}: no such file")
    size = float(path.stat().st_size)
    # the float32 pairs as read (the file's size), then padded into complex64 and the tree's pair
    check_resources(Estimate(3.0 * size, 0.0, [("samples", size)], keys="the pings in the file"),
                    what=where, max_memory_gb=max_memory_gb)
    try:
        nc = netCDF4.Dataset(path)
    except Exception as exc:
        raise DatasetError(f"{path}: cannot be read as netCDF4 ({exc.__class__.__name__})") from None
    with nc:
        gpath = f"Sonar/{beam_group}"
        bg, env, sonar = _group(nc, gpath), _group(nc, "Environment"), _group(nc, "Sonar")
        others = sorted(g for g in (sonar.groups if sonar is not None else {})
                        if g.startswith("Beam_group") and g != beam_group)
        if bg is None and others:
            raise DatasetError(f"{where}: no /{gpath}; its beam groups are {', '.join(others)} "
                               f"(choose one: beam_group=..., abacus convert --beam-group NAME)")
        if others:       # an EK80 writes one beam group per channel: say what is left out
            import warnings
            warnings.warn(f"{where}: read /{gpath}, one of {len(others) + 1} beam groups; the others "
                          f"({', '.join(others)}) are read with beam_group=... (abacus convert "
                          f"--beam-group NAME)", DatasetWarning, stacklevel=2)
        abacus = _var(bg, "subbeam_x") is not None
        need = [("Environment", env, "sound_speed_indicative")]
        need += [(gpath, bg, n) for n in ("backscatter_r", "backscatter_i", "ping_time", "sample_interval",
                                          "transmit_frequency_start", "transmit_frequency_stop",
                                          "transmit_pulse_model_r", "transmit_pulse_model_i", "beam_type")]
        btype_var = _var(bg, "beam_type")
        btype = int(np.asarray(_array(btype_var)).ravel()[0]) if btype_var is not None else None
        if btype == 1:
            raise DatasetError(f"{where}: /{gpath} holds power/angle samples (beam_type "
                               f"split_aperture_angles); abacus images complex samples per sub-beam "
                               f"(beam_type single or split_aperture_4_subbeams)")
        if abacus:
            need += [(gpath, bg, n) for n in ("subbeam_y", "subbeam_z", "subbeam_subarray")]
            need += [("Sonar", sonar, n) for n in ("tx_element_x", "tx_element_y", "tx_element_z")]
        elif btype not in (0, None):
            need += [(gpath, bg, n) for n in ("echoangle_major_sensitivity", "echoangle_minor_sensitivity")]
        missing = [f"/{g}" if grp is None else f"/{g}/{n}" for g, grp, n in need
                   if grp is None or _var(grp, n) is None]
        missing = list(dict.fromkeys(missing))
        if missing:
            raise DatasetError(f"{where}: SONAR-netCDF4 2.0 file lacks what abacus needs to read it "
                               f"({len(missing)}): {', '.join(missing)}")
        return _tree(nc, path, gpath, bg, env, sonar, btype, abacus)


def _tree(nc, path, gpath, bg, env, sonar, btype, abacus) -> xr.DataTree:
    where = str(path)
    re_cells = _cells(bg["backscatter_r"], 3)
    im_cells = _cells(bg["backscatter_i"], 3)
    if re_cells.ndim != 3 or re_cells.shape != im_cells.shape:
        raise DatasetError(f"{where}: /{gpath}/backscatter_r/_i must be (ping_time, beam, subbeam) and "
                           f"alike, found {bg['backscatter_r'].dimensions}")
    n_p, n_b, n_sb = re_cells.shape
    if n_b != 1:
        raise DatasetError(f"{where}: /{gpath} holds {n_b} beams; abacus reads one beam whose sub-beams "
                           f"are its elements (one beam group per beam)")
    if btype == 2 and n_sb != 4:
        raise DatasetError(f"{where}: /{gpath}: beam_type split_aperture_4_subbeams with {n_sb} sub-beams")
    if btype not in (0, 2) and not abacus:
        raise DatasetError(f"{where}: /{gpath}: beam_type {btype}; abacus reads single and "
                           f"split_aperture_4_subbeams beams (docs/dataset.md)")
    n_s = max((np.size(c) for c in re_cells.ravel()), default=0)
    x = np.zeros((n_p, n_sb, n_s), np.complex64)
    for p in range(n_p):
        for s in range(n_sb):
            r, i = np.asarray(re_cells[p, 0, s], np.float32), np.asarray(im_cells[p, 0, s], np.float32)
            if r.size != i.size:
                raise DatasetError(f"{where}: /{gpath}/backscatter_r and _i differ in length at ping {p}, "
                                   f"sub-beam {s}")
            x[p, s, :r.size] = r + 1j * i
    times = _times(bg["ping_time"], f"{where}: /{gpath}/ping_time")
    interval = _one(bg["sample_interval"], f"{where}: /{gpath}/sample_interval")
    f_start = _one(bg["transmit_frequency_start"], f"{where}: /{gpath}/transmit_frequency_start")
    f_stop = _one(bg["transmit_frequency_stop"], f"{where}: /{gpath}/transmit_frequency_stop")
    f0 = 0.5 * (f_start + f_stop)
    bw = abs(f_stop - f_start)
    if _var(bg, "transmit_bandwidth") is not None:
        bw = _one(bg["transmit_bandwidth"], f"{where}: /{gpath}/transmit_bandwidth")
    elif bw == 0 and _var(bg, "transmit_duration_nominal") is not None:      # CW: the pulse's own band
        bw = 1.0 / _one(bg["transmit_duration_nominal"], f"{where}: /{gpath}/transmit_duration_nominal")
    rep_r, rep_i = _array(bg["transmit_pulse_model_r"]), _array(bg["transmit_pulse_model_i"])
    if rep_r.dtype == object:                   # the convention's pulse_t: one vector per ping
        replica = np.asarray(rep_r.ravel()[0], float) + 1j * np.asarray(rep_i.ravel()[0], float)
    else:                                       # a fixed-length writer: the last axis is samples
        replica = rep_r.reshape(-1, rep_r.shape[-1])[0] + 1j * rep_i.reshape(-1, rep_i.shape[-1])[0]
    c = _one(env["sound_speed_indicative"], f"{where}: /Environment/sound_speed_indicative")
    blank, offset = (_one(bg[n], f"{where}: /{gpath}/{n}") if _var(bg, n) is not None else 0.0
                     for n in ("blanking_interval", "sample_time_offset"))

    if abacus:
        pos = np.stack([_array(bg[f"subbeam_{a}"]).astype(float) for a in "xyz"], -1)
        sub = _array(bg["subbeam_subarray"]).astype(str)
        names = _array(bg["subbeam"]).astype(str) if _var(bg, "subbeam") is not None else None
        idx = _array(bg["subbeam_index_in_subarray"]).astype(int) if _var(bg, "subbeam_index_in_subarray") \
            is not None else None
        tx = np.stack([_array(sonar[f"tx_element_{a}"]).astype(float) for a in "xyz"], -1)
        txw = _array(sonar["tx_element_weight"]).astype(float) if _var(sonar, "tx_element_weight") is not None \
            else np.ones(len(tx))
    elif btype == 2:
        lam = c / f0
        d = [_one(bg[f"echoangle_{a}_sensitivity"], f"{where}: /{gpath}/echoangle_{a}_sensitivity")
             * lam / (2 * np.pi) for a in ("major", "minor")]
        pos = np.array([[sx * d[0] / 2, sy * d[1] / 2, 0.0] for sx, sy, _ in SECTOR_LAYOUT])
        sub = np.array([s for *_, s in SECTOR_LAYOUT])
        names, idx = None, None
        tx, txw = np.zeros((1, 3)), np.ones(1)
    else:                                                                     # one single beam
        pos, sub, names, idx = np.zeros((n_sb, 3)), np.array(["A"] * n_sb), None, None
        tx, txw = np.zeros((1, 3)), np.ones(1)
    if names is None:
        counters: dict = {}
        names, idx = [], []
        for s in sub:
            idx.append(counters.get(s, 0))
            names.append(f"{s}{idx[-1]}")
            counters[s] = idx[-1] + 1
        names, idx = np.array(names), np.array(idx)
    mode = str(getattr(bg, "mode", "interferometric" if {"A", "B"} <= set(sub.tolist()) else "normal"))

    beams = {**{k: v[None].transpose(0, 1, 3, 2) for k, v in complex_pair("backscatter", x).items()},
             "beam_type": ["single"],
             "sample_interval": per_ping(interval, n_p), "blanking_interval": per_ping(blank, n_p),
             "sample_time_offset": per_ping(offset, n_p),
             "transmit_frequency_start": per_ping(f_start, n_p), "transmit_frequency_stop": per_ping(f_stop, n_p),
             "transmit_bandwidth": per_ping(bw, n_p),
             "element_x": pos[:, 0], "element_y": pos[:, 1], "element_z": pos[:, 2],
             "element_subarray": sub, "element_index_in_subarray": idx,
             "channel": [CHANNEL], "ping_time": times,
             "ping_index": _array(bg["ping_index"]).astype(int) if _var(bg, "ping_index") is not None
             else np.arange(n_p),
             "range_sample": np.arange(n_s), "beam": names}
    for a in ("width", "height", "rotation"):
        if _var(bg, f"subbeam_{a}") is not None:
            beams[f"element_{a}"] = _array(bg[f"subbeam_{a}"]).astype(float)
    if _var(bg, "adc_clipped_samples") is not None:
        beams["adc_clipped_samples"] = _array(bg["adc_clipped_samples"]).astype(int)
    if abacus:
        eba = (_array(bg["equivalent_beam_angle"]).astype(float)
               if _var(bg, "equivalent_beam_angle") is not None else None)
        if eba is not None and np.all(np.isfinite(eba)):
            beams["equivalent_beam_angle"] = per_beam(np.full(n_sb, 10 * np.log10(np.mean(eba))))
        for a in ("major", "minor"):
            v = _var(bg, f"beamwidth_receive_{a}")
            if v is not None and np.all(np.isfinite(_array(v))):
                beams[f"beamwidth_receive_{a}"] = per_beam(np.full(n_sb, float(np.mean(_array(v)))))
    battrs = {k: getattr(bg, k) for k in ("adc_scale_counts", "adc_quantized", "adc_bits", "noise_enabled",
                                          "noise_sigma_counts", "noise_bandwidth_hz", "receiver_bandwidth_hz")
              if k in bg.ncattrs()}
    battrs.update(mode=mode, beam_mode=str(getattr(bg, "beam_mode", "vertical")),
                  conversion_equation_type=f"SONAR-netCDF4 2.0 {gpath}: complex samples per sub-beam")

    svals = {**complex_pair("replica", replica.astype(np.complex64)),
             "transmit_frequency_start": f_start, "transmit_frequency_stop": f_stop,
             "transmit_frequency_center": f0, "transmit_bandwidth": bw,
             "tx_element_x": tx[:, 0], "tx_element_y": tx[:, 1], "tx_element_z": tx[:, 2], "tx_element_weight": txw,
             "beam_group_name": [BEAM_GROUP_NAME], "beam_group_descr": [f"{gpath} of {path.name}"],
             "channel_all": [CHANNEL], "beam_group": [BEAM_GROUP_NAME]}
    if _var(bg, "transmit_duration_nominal") is not None:
        svals["transmit_duration_nominal"] = _one(bg["transmit_duration_nominal"],
                                                  f"{where}: /{gpath}/transmit_duration_nominal")
    for a in ("major", "minor"):
        # a monostatic transducer (a foreign file) transmits with its receive beam
        v = _var(bg, f"beamwidth_transmit_{a}")
        if (v is None or not np.any(np.isfinite(_array(v)))) and not abacus:
            v = _var(bg, f"beamwidth_receive_{a}")
        if v is not None and np.any(np.isfinite(_array(v))):
            svals[f"beamwidth_transmit_{a}"] = _one(v, f"{where}: /{gpath}/{v.name}")
    for name in ("calibration_gain", "two_way_elevation_width", "calibration_azimuth", "tx_element_width",
                 "tx_element_height", "tx_element_rotation"):
        if _var(sonar, name) is not None:
            svals[name] = _array(sonar[name]).astype(float)
    sattrs = {k: str(getattr(sonar, k, "")) for k in ("sonar_manufacturer", "sonar_model", "sonar_serial_number",
                                                       "sonar_software_name", "sonar_software_version")}
    sattrs.update({k: str(getattr(sonar, k)) for k in ("taper", "sweep", "variant", "frame", "mode")
                   if k in sonar.ncattrs() and group_spec(SONAR_GROUP).attribute(k) is not None})
    sattrs["mode"] = mode

    env_vals = {"sound_speed_indicative": c}
    alpha = np.atleast_1d(_array(env["absorption_indicative"]).astype(float)) \
        if _var(env, "absorption_indicative") is not None else np.array([np.nan])
    if np.all(np.isfinite(alpha)):                   # NaN: the file does not know it
        freq = np.atleast_1d(_array(env["frequency"]).astype(float)) if _var(env, "frequency") is not None \
            else np.full(alpha.size, f0)
        env_vals.update(absorption_indicative=alpha, frequency=freq)
    for name in ("temperature", "salinity", "depth", "ph"):
        if _var(env, name) is not None:
            env_vals[name] = float(_array(env[name]))

    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    root = {"title": str(getattr(nc, "title", "")) or f"SONAR-netCDF4 2.0: {path.name}",
            # 1.0's keywords are the sonar model, as echopype reads them (2.0's list the sonar type too)
            "keywords": str(getattr(sonar, "sonar_model", "") or getattr(nc, "keywords", "")),
            "summary": str(getattr(nc, "summary", "")),
            "date_created": str(getattr(nc, "date_created", now)),
            "data_kind": str(getattr(nc, "data_kind", "recorded")), "source": str(path),
            "converted_from": "SONAR-netCDF4 2.0"}
    for k in ("software_name", "software_version"):
        if k in nc.ncattrs():
            root[k] = str(getattr(nc, k))
    groups = {ROOT_GROUP: build_group(ROOT_GROUP, {}, attrs=root),
              ENVIRONMENT_GROUP: build_group(ENVIRONMENT_GROUP, env_vals),
              SONAR_GROUP: build_group(SONAR_GROUP, svals, attrs=sattrs),
              ELEMENT_GROUP: build_group(ELEMENT_GROUP, beams, attrs=battrs)}
    plat = _group(nc, "Platform")
    if _var(plat, "sonar_rotation") is not None:
        pv = {"sonar_position": _array(plat["sonar_position"]).astype(float),
              "sonar_rotation": _array(plat["sonar_rotation"]).astype(float),
              "world_axis": ["x", "y", "z"], "sonar_axis": ["x", "y", "z"], "channel": [CHANNEL],
              **{f"transducer_offset_{a}": [float(_array(plat["sonar_position"])[i])] for i, a in enumerate("xyz")}}
        if _var(plat, "ping_sonar_rotation") is not None:
            pv.update(ping_sonar_position=_array(plat["ping_sonar_position"]).astype(float),
                      ping_sonar_rotation=_array(plat["ping_sonar_rotation"]).astype(float),
                      ping_time=_times(plat["ping_time"], f"{where}: /Platform/ping_time"),
                      roll=_array(bg["platform_roll"]).astype(float),
                      pitch=_array(bg["platform_pitch"]).astype(float),
                      heading=_array(bg["platform_heading"]).astype(float),
                      vertical_offset=_array(bg["platform_vertical_offset"]).astype(float))
        groups[PLATFORM_GROUP] = build_group(PLATFORM_GROUP, pv)
    prov = _group(nc, "Provenance")
    if abacus and prov is not None:
        kept = {k: str(prov.getncattr(k)) for k in ("scene_text", "scene_sha256", "seed") if k in prov.ncattrs()}
        if kept:
            groups[PROVENANCE_GROUP] = build_group(PROVENANCE_GROUP, {}, attrs=kept)
    truth = _group(nc, "Vendor_specific")
    if abacus and truth is not None and "target_ping_index" in truth.variables:
        groups[TRUTH_GROUP] = _truth(truth, where)
    return tree_of(groups)


def _truth(grp, where: str) -> xr.Dataset:
    """abacus' ground truth as the 1.0 table has it (times back to datetime64)."""
    spec = group_spec(TRUTH_GROUP)
    values = {}
    for name, var in grp.variables.items():
        if spec.variable(name) is None:
            continue
        values[name] = _times(var, f"{where}: /Vendor_specific/{name}") if name == "ping_time" else _array(var)
    if "truth_count_total" in grp.variables and "ping_time" in values:
        # written before the rows moved onto ping_time: one time per ping, rows per ping counted
        values["ping_time"] = np.repeat(values["ping_time"], _array(grp["truth_count_total"]).astype(int))
    attrs = {k: grp.getncattr(k) for k in grp.ncattrs() if spec.attribute(k) is not None}
    if "counting_range_m" in grp.ncattrs():                  # the layout before: one list
        attrs["counting_range_min_m"], attrs["counting_range_max_m"] = \
            (float(x) for x in np.ravel(grp.getncattr("counting_range_m")))
    attrs = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in attrs.items()}
    return build_group(TRUTH_GROUP, values, attrs=attrs)
