"""Other layouts brought to the data contract (SONAR-netCDF4 1.0, processing/base/dataset.py).

Two readers, one builder:

* :func:`from_legacy`: abacus' layout before SONAR-netCDF4 (``/Simulation/Element_group1`` with
  ``element_r/_i`` on (ping_time, rx_element, range_sample), ``/Simulation/Ground_truth``) — the
  groups are moved and renamed, nothing is recomputed, so calibration, platform, provenance and
  truth come along.
* :func:`read_mat`: MATLAB v5/v7 ``.mat`` files of per-element samples, as the thesis' recordings
  were kept (§6.4), with the field mapping of :data:`MAT_FIELDS`; v7.3 files are HDF5 and are
  refused with a message saying how to save them.
* :func:`record_tree`: the SONAR-netCDF4 tree of a record given as arrays — what a reader of any
  other format calls.

Every group is made (or, for the previous layout, brought to the contract's attributes) by
:mod:`processing.base.groups` from the contract's table, the builder the simulator uses too.

Every missing or malformed field is one :class:`processing.base.dataset.DatasetError` naming the file,
the field and what is accepted.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.contract import (BEAM_GROUP_NAME, CHANNEL, ELEMENT_GROUP, ENVIRONMENT_GROUP, GROUPS,
                                      LEGACY_ELEMENT_GROUP, LEGACY_TRUTH_GROUP, ROOT_GROUP, SONAR_GROUP,
                                      TRUTH_GROUP, node_path)
from processing.base.dataset import DatasetError
from processing.base.groups import build_group, complex_pair, conform_group, per_ping, tree_of

__all__ = ["record_tree", "from_legacy", "read_mat", "MAT_FIELDS", "CHANNEL"]

#: what /Sonar says the one beam group holds
BEAM_GROUP_DESCR = "complex baseband samples of every receive element: one beam per element"

#: .mat field -> (required, meaning); names are case-sensitive
MAT_FIELDS = {
    "samples": (True, "complex per-element baseband samples, n_pings x n_elements x n_samples "
                      "(or samples_r and samples_i, real); ADC counts or volts"),
    "fs": (True, "sampling rate (Hz)"),
    "f0": (True, "transmit centre frequency (Hz)"),
    "bandwidth": (True, "transmit bandwidth (Hz)"),
    "replica": (True, "complex transmit pulse sampled at fs (the matched filter's replica)"),
    "c": (True, "sound speed (m/s)"),
    "element_xyz": (True, "receive element centres, n_elements x 3 (m, sonar frame: x along the "
                          "receiver, y along the transmitter, z boresight)"),
    "element_subarray": (True, "subarray of each element: a char array or cell array of 'A'/'B'"),
    "tx_xyz": (True, "transmit element centres, n_tx x 3 (m, sonar frame)"),
    "tx_weight": (False, "transmit element weights, n_tx (default 1)"),
    "element_size": (False, "receive element width and height, n_elements x 2 (m)"),
    "tx_size": (False, "transmit element width and height, n_tx x 2 (m)"),
    "t0": (False, "time of sample 0 after the start of transmission (s, default 0)"),
    "alpha": (False, "absorption at f0 (dB/m)"),
    "ping_time": (False, "ping times, n_pings (s from the first ping)"),
    "mode": (False, "'interferometric' (default), 'normal' or 'combined'"),
    "tx_beamwidth_deg": (False, "transmit 3 dB beamwidths [azimuth, elevation] (deg): the default "
                                "counting volume"),
}


def record_tree(samples, *, rate_hz: float, center_frequency_hz: float, bandwidth_hz: float,
                replica, sound_speed_m_s: float, element_position_m, element_subarray,
                tx_position_m, tx_weight=None, element_size_m=None, tx_size_m=None,
                time_offset_s: float = 0.0, absorption_db_per_m: float | None = None,
                ping_time_s=None, mode: str = "interferometric", tx_beamwidth_deg=None,
                title: str = "recorded data", source: str = "") -> xr.DataTree:
    """The SONAR-netCDF4 tree of a per-element record.

    Parameters
    ----------
    samples : array_like, shape (n_pings, n_elements, n_samples), complex
        Per-element complex baseband samples.
    rate_hz, center_frequency_hz, bandwidth_hz, sound_speed_m_s : float
    replica : array_like, shape (M,), complex
        The transmit pulse at ``rate_hz``.
    element_position_m : array_like, shape (n_elements, 3)
    element_subarray : array_like of str, shape (n_elements,)
    tx_position_m : array_like, shape (n_tx, 3)
    tx_weight : array_like, shape (n_tx,), optional
    element_size_m, tx_size_m : array_like, shape (n, 2), optional
        Width and height (m); without them the element geometry for TS is absent (TS NaN).
    time_offset_s : float
        Time of sample 0 after the start of transmission.
    absorption_db_per_m : float, optional
    ping_time_s : array_like, shape (n_pings,), optional
        Seconds from the first ping (default 0, 1, 2, ...).
    mode : str
    tx_beamwidth_deg : (float, float), optional
        Transmit 3 dB beamwidths in azimuth and elevation (deg): the default counting volume.
    title, source : str

    Returns
    -------
    xarray.DataTree
        /, /Environment, /Sonar and /Sonar/Beam_group1 of the contract.

    Raises
    ------
    DatasetError
        A shape or value that does not fit (named, with what is accepted).
    """
    where = source or "record"
    x = np.asarray(samples)
    if x.ndim != 3 or 0 in x.shape:
        raise DatasetError(f"{where}: samples must be n_pings x n_elements x n_samples, got shape {x.shape}")
    n_p, n_e, n_s = x.shape
    pos = np.asarray(element_position_m, float)
    if pos.shape != (n_e, 3):
        raise DatasetError(f"{where}: element positions must be {n_e} x 3 (one row per element of the "
                           f"samples), got shape {pos.shape}")
    sub = np.asarray(element_subarray).astype(str).ravel()
    if sub.size != n_e:
        raise DatasetError(f"{where}: element_subarray must name {n_e} elements, got {sub.size}")
    tx = np.asarray(tx_position_m, float)
    if tx.ndim != 2 or tx.shape[1] != 3 or len(tx) == 0:
        raise DatasetError(f"{where}: transmit element positions must be n_tx x 3, got shape {tx.shape}")
    txw = np.ones(len(tx)) if tx_weight is None else np.asarray(tx_weight, float).ravel()
    if txw.size != len(tx):
        raise DatasetError(f"{where}: tx_weight must have one value per transmit element ({len(tx)})")
    for name, v in (("fs", rate_hz), ("f0", center_frequency_hz), ("bandwidth", bandwidth_hz),
                    ("c", sound_speed_m_s)):
        if not (np.isfinite(v) and v > 0):
            raise DatasetError(f"{where}: {name} must be a positive number, got {v}")
    t = np.arange(n_p, dtype=float) if ping_time_s is None else np.asarray(ping_time_s, float).ravel()
    if t.size != n_p:
        raise DatasetError(f"{where}: ping_time must have one value per ping ({n_p})")
    ping_time = np.datetime64("2000-01-01T00:00:00", "ns") + (t * 1e9).astype("timedelta64[ns]")
    names = []
    counters: dict = {}
    for s_ in sub:
        names.append(f"{s_}{counters.get(s_, 0)}")
        counters[s_] = counters.get(s_, 0) + 1
    # (ping, element, sample) -> (channel, ping_time, range_sample, beam): float32 views
    pair = {k: v[None].transpose(0, 1, 3, 2) for k, v in complex_pair("backscatter", x.astype(np.complex64)).items()}
    beams = {**pair,
             "beam_type": ["single"],
             "sample_interval": per_ping(1.0 / rate_hz, n_p), "blanking_interval": per_ping(time_offset_s, n_p),
             "sample_time_offset": per_ping(0.0, n_p),
             "transmit_frequency_start": per_ping(center_frequency_hz - bandwidth_hz / 2, n_p),
             "transmit_frequency_stop": per_ping(center_frequency_hz + bandwidth_hz / 2, n_p),
             "transmit_bandwidth": per_ping(bandwidth_hz, n_p),
             "element_x": pos[:, 0], "element_y": pos[:, 1], "element_z": pos[:, 2],
             "element_subarray": sub,
             "element_index_in_subarray": np.array([int(n[len(s_):]) for n, s_ in zip(names, sub)]),
             "channel": [CHANNEL], "ping_time": ping_time, "ping_index": np.arange(n_p),
             "range_sample": np.arange(n_s), "beam": names}
    if element_size_m is not None:
        beams.update(_sizes(element_size_m, n_e, "element", f"{where}: element_size"))
    sonar = {**complex_pair("replica", np.asarray(replica).ravel().astype(np.complex128)),
             "transmit_frequency_center": center_frequency_hz, "transmit_bandwidth": bandwidth_hz,
             "tx_element_x": tx[:, 0], "tx_element_y": tx[:, 1], "tx_element_z": tx[:, 2],
             "tx_element_weight": txw,
             "beam_group_name": [BEAM_GROUP_NAME], "beam_group_descr": [BEAM_GROUP_DESCR],
             "channel_all": [CHANNEL], "beam_group": [BEAM_GROUP_NAME]}
    if tx_beamwidth_deg is not None:
        bw = np.asarray(tx_beamwidth_deg, float).ravel()
        if bw.size != 2 or not np.all(bw > 0):
            raise DatasetError(f"{where}: tx_beamwidth_deg must be two positive angles [azimuth, elevation]")
        sonar.update(beamwidth_transmit_major=bw[0], beamwidth_transmit_minor=bw[1])
    if tx_size_m is not None:
        sonar.update(_sizes(tx_size_m, len(tx), "tx_element", f"{where}: tx_size"))
    env = {"sound_speed_indicative": float(sound_speed_m_s)}
    if absorption_db_per_m is not None:
        env.update(absorption_indicative=[float(absorption_db_per_m)], frequency=[float(center_frequency_hz)])
    root = {"keywords": "", "title": title, "data_kind": "recorded",
            "date_created": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
            "source": str(source)}
    return tree_of({ROOT_GROUP: build_group(ROOT_GROUP, {}, attrs=root),
                    ENVIRONMENT_GROUP: build_group(ENVIRONMENT_GROUP, env),
                    SONAR_GROUP: build_group(SONAR_GROUP, sonar, attrs={
                        "sonar_manufacturer": "", "sonar_model": "", "sonar_serial_number": "",
                        "sonar_software_name": "", "sonar_software_version": ""}),
                    ELEMENT_GROUP: build_group(ELEMENT_GROUP, beams, attrs={"mode": mode})})


def _sizes(size_m, n: int, prefix: str, where: str) -> dict:
    """``<prefix>_width/_height`` of n elements from an (n, 2) array, and rotations 0."""
    size = np.asarray(size_m, float)
    if size.size != 2 * n:
        raise DatasetError(f"{where} must be {n} x 2 (width, height in m)")
    size = size.reshape(n, 2)
    return {f"{prefix}_width": size[:, 0], f"{prefix}_height": size[:, 1], f"{prefix}_rotation": np.zeros(n)}


def from_legacy(tree: xr.DataTree, *, source: str = "") -> xr.DataTree:
    """The previous abacus layout moved to SONAR-netCDF4 (nothing recomputed).

    Raises
    ------
    DatasetError
        ``tree`` is not in the previous layout.
    """
    where = source or "dataset"
    try:
        old = tree[LEGACY_ELEMENT_GROUP].to_dataset(inherit=False)
    except KeyError:
        raise DatasetError(f"{where}: not the previous abacus layout (no /{LEGACY_ELEMENT_GROUP})") from None
    if "element_r" not in old or "element_i" not in old:
        raise DatasetError(f"{where}: /{LEGACY_ELEMENT_GROUP} has no element_r/element_i")
    names = (old["channel"].values.astype(str) if "channel" in old.coords
             else np.array([f"E{i}" for i in range(old.sizes["rx_element"])]))
    eg = old.drop_vars([v for v in ("channel", "rx_element") if v in old.variables])
    eg = eg.rename({"rx_element": "beam"}).assign_coords(beam=names, channel=[CHANNEL])
    n_p = eg.sizes["ping_time"]
    # the samples to (channel, ping_time, range_sample, beam); sample_time_offset was the time of
    # sample 0, which SONAR-netCDF4 calls the blanking interval
    new = build_group(ELEMENT_GROUP, {
        **{f"backscatter_{p}": eg[f"element_{p}"].values[None].transpose(0, 1, 3, 2) for p in "ri"},
        "blanking_interval": per_ping(float(old["sample_time_offset"].values), n_p),
        "sample_time_offset": per_ping(0.0, n_p),
        "sample_interval": per_ping(float(old["sample_interval"].values), n_p),
        "beam_type": ["single"]})
    for name, var in new.data_vars.items():
        if name.startswith("backscatter_"):      # what else the old samples said is kept
            var.attrs = {**old[name.replace("backscatter", "element")].attrs, **var.attrs}
    eg = eg.drop_vars(["element_r", "element_i", "sample_time_offset", "sample_interval"])
    for name, var in new.data_vars.items():
        eg[name] = var
    legacy = node_path(LEGACY_ELEMENT_GROUP)
    skip = {ROOT_GROUP, legacy, legacy.rsplit("/", 1)[0]}
    moved = {node_path(LEGACY_TRUTH_GROUP): node_path(TRUTH_GROUP)}
    out = {ROOT_GROUP: tree.to_dataset(inherit=False)}
    for node in tree.subtree:
        path = node_path(node.path)
        if path in skip:
            continue
        ds = node.to_dataset(inherit=False)
        path = moved.get(path, path)
        if path == node_path(SONAR_GROUP):
            ds = ds.assign_coords(channel_all=[CHANNEL], beam_group=[BEAM_GROUP_NAME])
            ds["beam_group_name"] = ("beam_group", [BEAM_GROUP_NAME])
            ds["beam_group_descr"] = ("beam_group", [BEAM_GROUP_DESCR])
        out[path] = ds
    out[node_path(ELEMENT_GROUP)] = eg
    out[ROOT_GROUP] = out[ROOT_GROUP].assign_attrs(
        keywords=str(out.get(node_path(SONAR_GROUP), xr.Dataset()).attrs.get("sonar_model", "")),
        converted_from=f"abacus layout before SONAR-netCDF4 ({legacy})")
    # every group the contract knows gets its units and attributes from the table; anything
    # else the old file held is moved as it was
    return tree_of({path: conform_group(path, ds) if path in GROUPS else ds for path, ds in out.items()})


def _mat_field(m, name, where, *, required=True):
    if name in m:
        return m[name]
    if required:
        raise DatasetError(f"{where}: missing field '{name}' ({MAT_FIELDS[name][1]}); the fields "
                           f"abacus reads are in docs/dataset.md, 'MATLAB files'")
    return None


def _scalar(m, name, where, *, required=True, default=None):
    v = _mat_field(m, name, where, required=required)
    if v is None:
        return default
    a = np.asarray(v, float).ravel()
    if a.size != 1 or not np.isfinite(a[0]):
        raise DatasetError(f"{where}: field '{name}' must be one finite number ({MAT_FIELDS[name][1]})")
    return float(a[0])


def _strings(v) -> np.ndarray:
    a = np.asarray(v)
    if a.dtype == object:                                  # cell array of strings
        return np.array([str(np.asarray(x).ravel()[0]) if np.asarray(x).size else "" for x in a.ravel()])
    if a.dtype.kind in "US":
        if a.ndim == 1 and a.size == 1 and len(str(a[0])) > 1:   # 'AABB': one char per element
            return np.array(list(str(a[0])))
        return np.array([str(x).strip() for x in a.ravel()])
    raise ValueError("not text")


def read_mat(path) -> xr.DataTree:
    """A MATLAB v5/v7 ``.mat`` recording of per-element samples as a SONAR-netCDF4 tree
    (fields: :data:`MAT_FIELDS`).

    Raises
    ------
    DatasetError
        Not a readable .mat file (v7.3 named), or a field missing or malformed.
    """
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError
    path = Path(path)
    where = str(path)
    with open(path, "rb") as fh:
        head = fh.read(128)
    if head[:8] == b"\x89HDF\r\n\x1a\n" or b"MATLAB 7.3" in head:
        raise DatasetError(f"{where}: a MATLAB v7.3 (HDF5) file; save it with save(..., '-v7') to "
                           f"read it here")
    try:
        m = loadmat(path, squeeze_me=True)
    except (MatReadError, ValueError, TypeError, OSError) as exc:
        raise DatasetError(f"{where}: not a readable MATLAB v5/v7 .mat file ({exc})") from None
    if "samples" in m:
        x = np.asarray(m["samples"])
    elif "samples_r" in m and "samples_i" in m:
        x = np.asarray(m["samples_r"], float) + 1j * np.asarray(m["samples_i"], float)
    else:
        _mat_field(m, "samples", where)
    if x.ndim == 2:                                        # squeeze_me dropped a single ping
        x = x[None]
    if not np.issubdtype(x.dtype, np.number) or not np.all(np.isfinite(x)):
        raise DatasetError(f"{where}: field 'samples' must hold finite numbers ({MAT_FIELDS['samples'][1]})")
    try:
        sub = _strings(_mat_field(m, "element_subarray", where))
    except ValueError:
        raise DatasetError(f"{where}: field 'element_subarray' must be text "
                           f"({MAT_FIELDS['element_subarray'][1]})") from None
    mode = str(m["mode"]) if "mode" in m else "interferometric"
    if mode not in ("interferometric", "normal", "combined"):
        raise DatasetError(f"{where}: field 'mode' is {mode!r}; accepted: interferometric, normal, combined")
    opt = {k: m[k] for k in ("tx_weight", "element_size", "tx_size", "ping_time", "tx_beamwidth_deg") if k in m}
    return record_tree(
        x, rate_hz=_scalar(m, "fs", where), center_frequency_hz=_scalar(m, "f0", where),
        bandwidth_hz=_scalar(m, "bandwidth", where), replica=np.asarray(_mat_field(m, "replica", where)),
        sound_speed_m_s=_scalar(m, "c", where),
        element_position_m=np.asarray(_mat_field(m, "element_xyz", where), float),
        element_subarray=sub, tx_position_m=np.atleast_2d(np.asarray(_mat_field(m, "tx_xyz", where), float)),
        tx_weight=opt.get("tx_weight"), element_size_m=opt.get("element_size"), tx_size_m=opt.get("tx_size"),
        time_offset_s=_scalar(m, "t0", where, required=False, default=0.0),
        absorption_db_per_m=_scalar(m, "alpha", where, required=False),
        ping_time_s=opt.get("ping_time"), mode=mode, tx_beamwidth_deg=opt.get("tx_beamwidth_deg"), title=f"converted from {path.name}", source=where)
