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
the field and what is accepted. What a converter writes is checked as strictly as processing reads
it (:func:`check_record`): the samples, replica and geometry are finite numbers, the replica is not
empty or all zero, the ping times are finite, strictly increasing and within ±100 years of the
first, the sound speed is that of water (:data:`SOUND_SPEED_M_S`, 1300–1800 m/s, the scene
schema's bounds), every element is in subarray A or B (both where the mode is interferometric or
combined), and the tree follows the contract's table (:func:`processing.base.groups.check_tree`).
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.contract import (BEAM_GROUP_NAME, CHANNEL, ELEMENT_GROUP, ENVIRONMENT_GROUP, GROUPS,
                                      LEGACY_ELEMENT_GROUP, LEGACY_TRUTH_GROUP, PROVENANCE_GROUP, ROOT_GROUP, SONAR_GROUP,
                                      TRUTH_GROUP, node_path)
from processing.base.dataset import DatasetError
from processing.base.groups import build_group, complex_pair, conform_group, per_ping, tree_of

__all__ = ["record_tree", "from_legacy", "read_mat", "check_record", "open_record", "RECORD_KINDS", "MAT_FIELDS", "CHANNEL",
           "SOUND_SPEED_M_S", "PING_TIME_SPAN_S", "MAT_MAX_BYTES"]

#: sound speeds a record may claim (m/s): water from fresh to salt, 0 to 40 °C, at any depth a
#: sonar works in (≈ 1400–1560 m/s) with a margin; the scene schema's bounds
SOUND_SPEED_M_S = (1300.0, 1800.0)
#: ping times of a record lie within this many seconds of its first ping (100 years): a time
#: further away overflows the nanosecond times of the file (datetime64[ns] spans 1678–2262)
PING_TIME_SPAN_S = 100 * 365.25 * 86400.0
#: the subarrays a receive element may belong to
SUBARRAYS = ("A", "B")
#: the largest .mat file read (bytes); the samples are held in memory anyway
MAT_MAX_BYTES = 64 << 30

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
    if mode not in ("interferometric", "normal", "combined"):
        raise DatasetError(f"{where}: mode {str(mode)[:40]!r}; accepted: interferometric, normal, combined")
    x = _samples(samples, where)
    n_p, n_e, n_s = x.shape
    pos = _real(element_position_m, "element_xyz", where)
    if pos.shape != (n_e, 3):
        raise DatasetError(f"{where}: element positions must be {n_e} x 3 (one row per element of the "
                           f"samples), got shape {pos.shape}")
    sub = _subarrays(element_subarray, n_e, mode, where)
    tx = _real(tx_position_m, "tx_xyz", where)
    if tx.ndim != 2 or tx.shape[1] != 3 or len(tx) == 0:
        raise DatasetError(f"{where}: transmit element positions must be n_tx x 3, got shape {tx.shape}")
    txw = np.ones(len(tx)) if tx_weight is None else _real(tx_weight, "tx_weight", where).ravel()
    if txw.size != len(tx):
        raise DatasetError(f"{where}: tx_weight must have one value per transmit element ({len(tx)})")
    if not np.any(txw):
        raise DatasetError(f"{where}: field 'tx_weight' is all zero: nothing is transmitted "
                           f"({MAT_FIELDS['tx_weight'][1]})")
    rate_hz, center_frequency_hz, bandwidth_hz, sound_speed_m_s = (
        _one(v, name, where) for name, v in (("fs", rate_hz), ("f0", center_frequency_hz),
                                             ("bandwidth", bandwidth_hz), ("c", sound_speed_m_s)))
    for name, v in (("fs", rate_hz), ("f0", center_frequency_hz), ("bandwidth", bandwidth_hz),
                    ("c", sound_speed_m_s)):
        if not v > 0:
            raise DatasetError(f"{where}: {name} must be a positive number, got {v}")
    lo, hi = SOUND_SPEED_M_S
    if not lo <= sound_speed_m_s <= hi:
        raise DatasetError(f"{where}: field 'c' (sound speed) is {sound_speed_m_s:.6g} m/s; accepted: "
                           f"{lo:.0f}–{hi:.0f} m/s (water)")
    if bandwidth_hz > rate_hz:
        raise DatasetError(f"{where}: field 'bandwidth' ({bandwidth_hz:.6g} Hz) exceeds the sampling rate "
                           f"'fs' ({rate_hz:.6g} Hz): complex baseband samples hold at most fs")
    time_offset_s = _one(time_offset_s, "t0", where)
    if absorption_db_per_m is not None:
        absorption_db_per_m = _one(absorption_db_per_m, "alpha", where)
        if absorption_db_per_m < 0:
            raise DatasetError(f"{where}: field 'alpha' must be >= 0 dB/m, got {absorption_db_per_m}")
    rep = _replica(replica, where)
    t = np.arange(n_p, dtype=float) if ping_time_s is None else _real(ping_time_s, "ping_time", where).ravel()
    if t.size != n_p:
        raise DatasetError(f"{where}: ping_time must have one value per ping ({n_p})")
    _check_ping_seconds(t, where)
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
    sonar = {**complex_pair("replica", rep),
             "transmit_frequency_center": center_frequency_hz, "transmit_bandwidth": bandwidth_hz,
             "tx_element_x": tx[:, 0], "tx_element_y": tx[:, 1], "tx_element_z": tx[:, 2],
             "tx_element_weight": txw,
             "beam_group_name": [BEAM_GROUP_NAME], "beam_group_descr": [BEAM_GROUP_DESCR],
             "channel_all": [CHANNEL], "beam_group": [BEAM_GROUP_NAME]}
    if tx_beamwidth_deg is not None:
        bw = _real(tx_beamwidth_deg, "tx_beamwidth_deg", where).ravel()
        if bw.size != 2 or not np.all(bw > 0) or not np.all(bw <= 360):
            raise DatasetError(f"{where}: tx_beamwidth_deg must be two angles in (0, 360] degrees "
                               f"[azimuth, elevation]")
        sonar.update(beamwidth_transmit_major=bw[0], beamwidth_transmit_minor=bw[1])
    if tx_size_m is not None:
        sonar.update(_sizes(tx_size_m, len(tx), "tx_element", f"{where}: tx_size"))
    env = {"sound_speed_indicative": float(sound_speed_m_s)}
    if absorption_db_per_m is not None:
        env.update(absorption_indicative=[float(absorption_db_per_m)], frequency=[float(center_frequency_hz)])
    root = {"keywords": "", "title": title, "data_kind": "recorded",
            "date_created": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
            "source": str(source)}
    created = root["date_created"]
    from processing.base.lazy import distribution_version
    # what echopype's Provenance holds: its combine_echodata reads it
    provenance = {"conversion_software_name": "abacus",
                  "conversion_software_version": distribution_version("abacus"), "conversion_time": created}
    tree = tree_of({ROOT_GROUP: build_group(ROOT_GROUP, {}, attrs=root),
                    PROVENANCE_GROUP: build_group(PROVENANCE_GROUP, {"source_filenames": [str(source)],
                                                                     "filenames": [0]}, attrs=provenance),
                    ENVIRONMENT_GROUP: build_group(ENVIRONMENT_GROUP, env),
                    SONAR_GROUP: build_group(SONAR_GROUP, sonar, attrs={
                        "sonar_manufacturer": "", "sonar_model": "", "sonar_serial_number": "",
                        "sonar_software_name": "", "sonar_software_version": ""}),
                    ELEMENT_GROUP: build_group(ELEMENT_GROUP, beams, attrs={"mode": mode})})
    check_record(tree, source=where)
    return tree


def _kind_name(a: np.ndarray) -> str:
    return {"U": "text", "S": "text", "c": "complex numbers", "O": "a cell array or struct",
            "M": "dates", "m": "durations", "V": "a struct"}.get(a.dtype.kind, f"values of type {a.dtype}")


def _field_help(name: str) -> str:
    return f" ({MAT_FIELDS[name][1]})" if name in MAT_FIELDS else ""


def _real(value, name: str, where: str) -> np.ndarray:
    """``value`` as a float array of finite numbers; text, cells, structs, complex values and NaN
    or inf refused, naming the field and what it holds."""
    try:
        a = np.asarray(value)
    except (ValueError, TypeError):     # ragged nested lists
        raise DatasetError(f"{where}: field '{name}' is not an array of numbers{_field_help(name)}") from None
    if a.dtype.kind not in "biuf":
        raise DatasetError(f"{where}: field '{name}' holds {_kind_name(a)}, not real numbers{_field_help(name)}")
    a = a.astype(float)
    if not np.all(np.isfinite(a)):
        raise DatasetError(f"{where}: field '{name}' holds NaN or inf; give finite numbers{_field_help(name)}")
    return a


def _one(value, name: str, where: str) -> float:
    """One finite real number (a scalar or a 1-element array)."""
    a = _real(value, name, where).ravel()
    if a.size != 1:
        raise DatasetError(f"{where}: field '{name}' must be one number, got {a.size}{_field_help(name)}")
    return float(a[0])


def _samples(samples, where: str) -> np.ndarray:
    """The samples as an (n_pings, n_elements, n_samples) array of finite numbers."""
    try:
        x = np.asarray(samples)
    except (ValueError, TypeError):
        raise DatasetError(f"{where}: field 'samples' is not an array of numbers{_field_help('samples')}") from None
    if x.dtype.kind not in "biufc":
        raise DatasetError(f"{where}: field 'samples' holds {_kind_name(x)}, not numbers{_field_help('samples')}")
    if x.ndim != 3 or 0 in x.shape:
        raise DatasetError(f"{where}: samples must be n_pings x n_elements x n_samples, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise DatasetError(f"{where}: field 'samples' must hold finite numbers{_field_help('samples')}")
    return x


def _replica(replica, where: str) -> np.ndarray:
    """The transmit pulse: a non-empty vector of finite numbers, not all zero (complex128)."""
    try:
        r = np.asarray(replica)
    except (ValueError, TypeError):
        r = np.asarray([], object)
    if r.dtype.kind not in "biufc":
        raise DatasetError(f"{where}: field 'replica' holds {_kind_name(r)}, not numbers{_field_help('replica')}")
    r = r.ravel().astype(np.complex128)
    if r.size == 0 or not np.all(np.isfinite(r)) or not np.any(r):
        raise DatasetError(f"{where}: field 'replica' (the transmit pulse) is empty, all zero or not finite: "
                           f"nothing to compress the echoes with{_field_help('replica')}")
    return r


def _subarrays(value, n_elements: int, mode: str, where: str) -> np.ndarray:
    """The subarray letter of every element: a sequence of 'A'/'B' strings, or one string of
    letters (MATLAB's char row 'AAAA…BBBB', or a char matrix read row by row)."""
    try:
        a = np.asarray(value)
    except (ValueError, TypeError):
        a = np.asarray([], object)
    if a.dtype.kind == "O":                       # a cell array of strings
        try:
            a = np.array([str(np.asarray(x).ravel()[0]) if np.asarray(x).size else "" for x in a.ravel()])
        except (ValueError, TypeError):
            a = np.asarray([], object)
    if a.dtype.kind not in "US":
        raise DatasetError(f"{where}: field 'element_subarray' must be text{_field_help('element_subarray')}")
    sub = np.array([str(x).strip() for x in a.ravel()])
    if sub.size != n_elements and sub.size and all(len(x) > 1 for x in sub):
        letters = "".join("".join(x.split()) for x in sub)   # a char row, or rows of letters
        if len(letters) == n_elements:
            sub = np.array(list(letters))
    if sub.size != n_elements:
        raise DatasetError(f"{where}: element_subarray must name {n_elements} elements, got {sub.size}")
    _check_subarrays(sub, mode, where, "field 'element_subarray'")
    return sub


def _check_subarrays(sub: np.ndarray, mode: str, where: str, what: str) -> None:
    bad = sorted(set(sub.tolist()) - set(SUBARRAYS))
    if bad:
        shown = ", ".join(repr(b[:8]) for b in bad[:4]) + (", ..." if len(bad) > 4 else "")
        raise DatasetError(f"{where}: {what} holds {shown}; accepted: 'A' or 'B' per element (the two "
                           f"receive subarrays)")
    present = set(sub.tolist())
    if mode in ("interferometric", "combined") and present != set(SUBARRAYS):
        raise DatasetError(f"{where}: mode {mode!r} needs elements in both subarrays A and B, found only "
                           f"{', '.join(sorted(present))}: give mode 'normal' for one subarray")


def _check_ping_seconds(t: np.ndarray, where: str) -> None:
    """Ping times in seconds: within :data:`PING_TIME_SPAN_S` and strictly increasing."""
    far = np.flatnonzero(np.abs(t) > PING_TIME_SPAN_S)
    if far.size:
        raise DatasetError(f"{where}: field 'ping_time' of ping {far[0]} is {t[far[0]]:.6g} s; accepted: "
                           f"seconds from the first ping, within ±{PING_TIME_SPAN_S:.4g} s (100 years)")
    _check_increasing(t, where, "field 'ping_time'", unit=" s")


def _check_increasing(t: np.ndarray, where: str, what: str, unit: str = "") -> None:
    back = np.flatnonzero(~(np.diff(t) > 0))
    if back.size:
        i = int(back[0]) + 1
        raise DatasetError(f"{where}: {what} must increase from ping to ping: ping {i} ({t[i]}{unit}) "
                           f"does not come after ping {i - 1} ({t[i - 1]}{unit})")


def check_record(tree: xr.DataTree, *, source: str = "") -> None:
    """Refuse a converted tree that processing could not use, as strictly as its readers
    (:func:`processing.base.dataset.read_record`, :func:`processing.base.groups.check_tree`)
    and the physics: finite samples and geometry, a replica that is not empty or all zero,
    ping times that are valid and strictly increasing, a sound speed of water
    (:data:`SOUND_SPEED_M_S`), subarrays A and B as the mode says, positive frequencies and
    sampling interval.

    Raises
    ------
    DatasetError
        One line naming the file, the variable and what is accepted.
    """
    from processing.base.dataset import group_of, read_record
    from processing.base.groups import check_tree
    where = source or "record"
    eg = group_of(tree, ELEMENT_GROUP)
    if eg is not None:
        mode = str(eg.attrs.get("mode", "interferometric"))
        if "element_subarray" in eg.variables:
            _check_subarrays(np.asarray(eg["element_subarray"].values).astype(str), mode, where,
                             f"/{ELEMENT_GROUP}/element_subarray")
        if "ping_time" in eg.variables:
            t = eg["ping_time"].values
            if np.issubdtype(t.dtype, np.datetime64):
                if np.isnat(t).any():
                    raise DatasetError(f"{where}: /{ELEMENT_GROUP}/ping_time holds a missing time (NaT) at "
                                       f"ping {int(np.flatnonzero(np.isnat(t))[0])}; every ping needs its time")
                _check_increasing(t, where, f"/{ELEMENT_GROUP}/ping_time")
            elif t.dtype.kind in "iuf":
                if not np.all(np.isfinite(t)):
                    raise DatasetError(f"{where}: /{ELEMENT_GROUP}/ping_time holds NaN or inf")
                _check_increasing(t, where, f"/{ELEMENT_GROUP}/ping_time")
            else:
                raise DatasetError(f"{where}: /{ELEMENT_GROUP}/ping_time holds {_kind_name(t)}, not times")
    import warnings
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = read_record(tree, source=where)
    except DatasetError:
        raise
    except (ValueError, TypeError) as exc:     # text where the reader wants numbers
        raise DatasetError(f"{where}: a variable processing reads holds values that are not numbers "
                           f"({str(exc).splitlines()[0][:120] if str(exc) else exc.__class__.__name__})") from None
    for name, v in (("/Sonar/transmit_frequency_center", rec.center_frequency_hz),
                    ("/Sonar/transmit_bandwidth", rec.bandwidth_hz),
                    (f"/{ELEMENT_GROUP}/sample_interval", 1.0 / rec.rate_hz)):
        if not (np.isfinite(v) and v > 0):
            raise DatasetError(f"{where}: {name} is {v}; accepted: a positive number")
    lo, hi = SOUND_SPEED_M_S
    if not (np.isfinite(rec.sound_speed_m_s) and lo <= rec.sound_speed_m_s <= hi):
        raise DatasetError(f"{where}: /Environment/sound_speed_indicative is {rec.sound_speed_m_s:.6g} m/s; "
                           f"accepted: {lo:.0f}–{hi:.0f} m/s (water)")
    for name, a in ((f"/{ELEMENT_GROUP}/element_x/_y/_z", rec.element_position_m),
                    ("/Sonar/tx_element_x/_y/_z", rec.transmitter_position_m),
                    ("/Sonar/tx_element_weight", rec.transmitter_weight)):
        if not np.all(np.isfinite(np.asarray(a, float))):
            raise DatasetError(f"{where}: {name} holds NaN or inf; give finite numbers")
    if not np.any(rec.transmitter_weight):
        raise DatasetError(f"{where}: /Sonar/tx_element_weight is all zero: nothing is transmitted")
    problems = check_tree(tree)
    if problems:
        more = f" (and {len(problems) - 3} more)" if len(problems) > 3 else ""
        raise DatasetError(f"{where}: does not follow the data contract (docs/dataset.md): "
                           f"{'; '.join(problems[:3])}{more}")


def _sizes(size_m, n: int, prefix: str, where: str) -> dict:
    """``<prefix>_width/_height`` of n elements from an (n, 2) array, and rotations 0."""
    file, _, name = where.rpartition(": ")
    size = _real(size_m, name, file)
    if size.size != 2 * n or not np.all(size > 0):
        raise DatasetError(f"{where} must be {n} x 2 positive sizes (width, height in m)")
    size = size.reshape(n, 2)
    return {f"{prefix}_width": size[:, 0], f"{prefix}_height": size[:, 1], f"{prefix}_rotation": np.zeros(n)}


#: what the previous layout must hold for a conversion processing can read: group -> variables
LEGACY_NEEDS = {
    LEGACY_ELEMENT_GROUP: ("element_r", "element_i", "sample_interval", "sample_time_offset", "element_x",
                           "element_y", "element_z", "element_subarray", "ping_time"),
    SONAR_GROUP: ("replica_r", "replica_i", "transmit_frequency_center", "transmit_bandwidth", "tx_element_x",
                  "tx_element_y", "tx_element_z", "tx_element_weight"),
    ENVIRONMENT_GROUP: ("sound_speed_indicative",),
}
#: the dimensions of the previous layout's samples
LEGACY_SAMPLE_DIMS = ("ping_time", "rx_element", "range_sample")


def _check_legacy(tree: xr.DataTree, old: xr.Dataset, where: str) -> None:
    """Every variable the conversion needs is present (all the missing ones named in one
    message), the numbers are numbers and the samples have the previous layout's dimensions."""
    from processing.base.dataset import group_of
    missing, wrong = [], []
    for group, names in LEGACY_NEEDS.items():
        ds = old if group == LEGACY_ELEMENT_GROUP else group_of(tree, group)
        for name in names:
            if ds is None or name not in ds.variables:
                missing.append(f"/{node_path(group).strip('/')}/{name}")
            elif name not in ("element_subarray", "ping_time") and ds[name].dtype.kind not in "biuf":
                wrong.append(f"/{node_path(group).strip('/')}/{name} ({_kind_name(ds[name])})")
    if missing:
        raise DatasetError(f"{where}: the previous abacus layout lacks {len(missing)} variable"
                           f"{'s' if len(missing) > 1 else ''} abacus convert needs: {', '.join(missing)}")
    if wrong:
        raise DatasetError(f"{where}: {', '.join(wrong)}: not numbers; the previous abacus layout holds "
                           f"numbers there")
    for p in "ri":
        dims = tuple(old[f"element_{p}"].dims)
        if dims != LEGACY_SAMPLE_DIMS:
            raise DatasetError(f"{where}: /{LEGACY_ELEMENT_GROUP}/element_{p} has dims {dims}; the previous "
                               f"layout has {LEGACY_SAMPLE_DIMS}")
    if old["element_r"].shape != old["element_i"].shape or 0 in old["element_r"].shape:
        raise DatasetError(f"{where}: /{LEGACY_ELEMENT_GROUP}/element_r/_i are empty or differ in shape")
    for name in ("sample_interval", "sample_time_offset"):
        if old[name].size != 1:
            raise DatasetError(f"{where}: /{LEGACY_ELEMENT_GROUP}/{name} must be one number (one setting "
                               f"for the record), found {old[name].size}")


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
    _check_legacy(tree, old, where)
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
    converted = tree_of({path: conform_group(path, ds) if path in GROUPS else ds for path, ds in out.items()})
    check_record(converted, source=where)
    return converted


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
    return _one(v, name, where)


def _open_mat(path: Path, max_memory_gb: float | None):
    """Gate a .mat file (a regular file: a FIFO or a device is refused before it is opened),
    refuse v7.3, check its memory against the limit, then load it."""
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    from processing.base.files import FileRefused, check_file
    from processing.base.resources import Estimate, check_resources
    where = str(path)
    accepts = "a MATLAB v5/v7 .mat file"
    try:
        f = check_file(path, max_bytes=MAT_MAX_BYTES, what="MATLAB file", accepts=accepts)
    except FileRefused as exc:
        raise DatasetError(str(exc)) from None
    # loaded whole; the samples then made complex64 and split into float32 pairs: ≈ 3 copies
    check_resources(Estimate(3.0 * f.size, 0.0, [("MATLAB file", float(f.size))],
                             keys="the pings in the file (save it in parts)"),
                    what=where, max_memory_gb=max_memory_gb)
    import os
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(path, flags)
        with os.fdopen(fd, "rb") as fh:
            head = fh.read(128)
    except OSError as exc:
        raise DatasetError(f"{where}: cannot be read ({exc.strerror or exc.__class__.__name__}); "
                           f"give {accepts}") from None
    if head[:8] == b"\x89HDF\r\n\x1a\n" or b"MATLAB 7.3" in head:
        raise DatasetError(f"{where}: a MATLAB v7.3 (HDF5) file; save it with save(..., '-v7') to "
                           f"read it here")
    try:
        return loadmat(path, squeeze_me=True)
    except (MatReadError, ValueError, TypeError, OSError, EOFError, KeyError, IndexError,
            NotImplementedError, UnicodeDecodeError, OverflowError) as exc:
        text = str(exc).splitlines()[0][:120] if str(exc) else exc.__class__.__name__
        raise DatasetError(f"{where}: not a readable MATLAB v5/v7 .mat file ({text})") from None


def read_mat(path, *, max_memory_gb: float | None = None) -> xr.DataTree:
    """A MATLAB v5/v7 ``.mat`` recording of per-element samples as a SONAR-netCDF4 tree
    (fields: :data:`MAT_FIELDS`), checked as processing reads it (:func:`check_record`).

    Parameters
    ----------
    path : str or Path
        A regular file (a FIFO or device is refused before it is opened).
    max_memory_gb : float, optional
        The memory limit (default: processing.base.resources.memory_limit_bytes).

    Raises
    ------
    DatasetError
        Not a readable .mat file (v7.3 named), fields missing (all named in one message) or
        malformed (text where numbers belong, NaN, a replica all zero, ...).
    processing.base.resources.ResourceError
        The file would not fit the memory limit.
    """
    path = Path(path)
    where = str(path)
    m = _open_mat(path, max_memory_gb)
    missing = [k for k, (required, _) in MAT_FIELDS.items() if required and k not in m
               and not (k == "samples" and "samples_r" in m and "samples_i" in m)]
    if missing:
        listed = "; ".join(f"'{k}' ({MAT_FIELDS[k][1]})" for k in missing)
        raise DatasetError(f"{where}: missing field{'s' if len(missing) > 1 else ''} {listed}; the fields "
                           f"abacus reads are in docs/dataset.md, 'MATLAB files'")
    if "samples" in m:
        x = np.asarray(m["samples"])
    else:
        x = _real(m["samples_r"], "samples_r", where) + 1j * _real(m["samples_i"], "samples_i", where)
    if x.ndim == 2:                                        # squeeze_me dropped a single ping
        x = x[None]
    if x.dtype.kind not in "biufc" or not np.all(np.isfinite(x)):
        raise DatasetError(f"{where}: field 'samples' must hold finite numbers ({MAT_FIELDS['samples'][1]})")
    mode = m["mode"] if "mode" in m else "interferometric"
    mode = str(mode) if isinstance(mode, (str, np.str_)) or np.asarray(mode).dtype.kind in "US" else repr(mode)
    if mode not in ("interferometric", "normal", "combined"):
        raise DatasetError(f"{where}: field 'mode' is {mode[:40]!r}; accepted: interferometric, normal, combined")
    n_e = x.shape[1] if x.ndim == 3 else 0
    sub = _subarrays(m["element_subarray"], n_e, mode, where) if n_e else m["element_subarray"]
    opt = {k: m[k] for k in ("tx_weight", "element_size", "tx_size", "ping_time", "tx_beamwidth_deg") if k in m}
    return record_tree(
        x, rate_hz=_scalar(m, "fs", where), center_frequency_hz=_scalar(m, "f0", where),
        bandwidth_hz=_scalar(m, "bandwidth", where), replica=_replica(m["replica"], where),
        sound_speed_m_s=_scalar(m, "c", where),
        element_position_m=_real(m["element_xyz"], "element_xyz", where),
        element_subarray=sub, tx_position_m=np.atleast_2d(_real(m["tx_xyz"], "tx_xyz", where)),
        tx_weight=opt.get("tx_weight"), element_size_m=opt.get("element_size"), tx_size_m=opt.get("tx_size"),
        time_offset_s=_scalar(m, "t0", where, required=False, default=0.0),
        absorption_db_per_m=_scalar(m, "alpha", where, required=False),
        ping_time_s=opt.get("ping_time"), mode=mode, tx_beamwidth_deg=opt.get("tx_beamwidth_deg"),
        title=f"converted from {path.name}", source=where)


#: what :func:`open_record` reads (for messages)
RECORD_KINDS = ("abacus SONAR-netCDF4 1.0 (.nc/.zarr)", "the previous abacus layout",
                "a MATLAB v5/v7 .mat recording", "a SONAR-netCDF4 2.0 file", "a Simrad EK60/EK80 file converted by echopype")


def open_record(path, *, max_memory_gb: float | None = None, beam_group: str = "Beam_group1") -> xr.DataTree:
    """Any recording abacus reads, as a checked tree.

    * ``.mat``: :func:`read_mat`;
    * a SONAR-netCDF4 2.0 file (:func:`processing.base.sonar_netcdf2_read.read_sonar_netcdf2`),
      its beam group ``beam_group`` (an EK80 writes one per channel);
    * the previous abacus layout: :func:`from_legacy`;
    * a Simrad EK60/EK80 file echopype converted (``echopype.open_raw(...).to_netcdf``): checked
      by :func:`processing.base.echosounder.check_echosounder` (every missing variable named in
      one message), its NaN documented (:func:`processing.base.echosounder.annotate_missing`),
      its values unchanged; ``abacus sv`` calibrates it;
    * a SONAR-netCDF4 file of per-element samples (abacus' own, or one written by hand): read
      by :func:`processing.base.dataset.read_record`, every missing variable named at once.

    Parameters
    ----------
    path : str or Path
    max_memory_gb : float, optional
    beam_group : str
        The beam group of a 2.0 file to read.

    Returns
    -------
    xarray.DataTree

    Raises
    ------
    DatasetError
        Unreadable, or not one of :data:`RECORD_KINDS`, or incomplete (all that is missing named).
    """
    from processing.base.dataset import has_group, open_tree, read_record
    from processing.base.echosounder import annotate_missing, check_echosounder, echosounder_model
    from processing.base.sonar_netcdf2 import is_sonar_netcdf2
    path = Path(path)
    where = str(path)
    if path.suffix.lower() == ".mat":
        return read_mat(path, max_memory_gb=max_memory_gb)
    if is_sonar_netcdf2(path):
        from processing.base.sonar_netcdf2_read import read_sonar_netcdf2
        tree = read_sonar_netcdf2(path, max_memory_gb=max_memory_gb, beam_group=beam_group)
        check_record(tree, source=where)
        return tree
    tree = open_tree(path, max_memory_gb=max_memory_gb, work_factor=2.0)
    if has_group(tree, LEGACY_ELEMENT_GROUP) and not has_group(tree, ELEMENT_GROUP):
        return from_legacy(tree, source=where)
    if echosounder_model(tree) is not None:
        check_echosounder(tree, source=where)
        return annotate_missing(tree)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        read_record(tree, source=where)
    return tree
