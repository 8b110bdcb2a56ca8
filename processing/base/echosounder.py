"""Files echopype converts from Simrad echosounders (EK60, EK80), read as processing needs them.

echopype (``echopype.open_raw(..., sonar_model="EK60").to_netcdf(...)``) writes SONAR-netCDF4
1.0 with one *channel* per transceiver/transducer pair, each beam group holding what that
echosounder records (echopype's ``echodata/convention/1.0.yml``):

* EK60 (and EK80 in its power mode, GPT transceivers): ``backscatter_r`` on (channel, ping_time,
  range_sample), the received power in dB re 1 W, and for split-beam channels the
  ``angle_alongship``/``angle_athwartship`` electrical angles; the calibration in /Vendor_specific
  (``gain_correction``, ``sa_correction`` per ``pulse_length``) and the beam group
  (``equivalent_beam_angle``, ``transmit_power``, ``transmit_duration_nominal``);
* EK80 complex (WBT transceivers): ``backscatter_r``/``_i`` on (channel, ping_time,
  range_sample, beam), one beam per transducer sector: 4 (or 3) for split-beam channels, 1 for
  single-beam ones.

:func:`echosounder_model` tells such a file from abacus' own (which holds one channel whose
beams are array elements, with ``element_subarray``); :func:`check_echosounder` lists *every*
variable the file lacks in one message; :func:`read_power_record` gives the power record the
EK60 calibration (:mod:`processing.backscatter.ek60`) turns into Sv.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from processing.base.contract import ELEMENT_GROUP, ENVIRONMENT_GROUP, TRUTH_GROUP
from processing.base.dataset import SIMRAD_MODELS, DatasetError, echosounder_model, group_of

__all__ = ["SIMRAD_MODELS", "echosounder_model", "check_echosounder", "PowerRecord", "read_power_record",
           "is_power_record", "ECHOSOUNDER_NEEDS", "annotate_missing", "FOREIGN_NAN_MEANS"]

_BG = ELEMENT_GROUP           # echopype's first beam group is the contract's: /Sonar/Beam_group1
_VEND = TRUTH_GROUP           # /Vendor_specific: abacus' ground truth, a Simrad file's calibration

#: what each encoding needs, group -> variables (a coordinate counts)
ECHOSOUNDER_NEEDS = {
    "power": {
        _BG: ("channel", "ping_time", "range_sample", "backscatter_r", "frequency_nominal", "sample_interval",
              "transmit_power", "transmit_duration_nominal", "equivalent_beam_angle"),
        ENVIRONMENT_GROUP: ("sound_speed_indicative", "absorption_indicative"),
        _VEND: ("gain_correction", "sa_correction", "pulse_length"),
    },
    "complex": {
        _BG: ("channel", "ping_time", "range_sample", "beam", "backscatter_r", "backscatter_i",
              "frequency_nominal", "sample_interval", "transmit_power", "transmit_duration_nominal",
              "transmit_frequency_start", "transmit_frequency_stop", "equivalent_beam_angle", "beam_type"),
        ENVIRONMENT_GROUP: ("sound_speed_indicative",),
        _VEND: ("gain_correction", "sa_correction", "pulse_length"),
    },
}
#: what a split-beam power channel adds (echopype's beam_type 1: angles recorded)
SPLIT_BEAM_NEEDS = ("angle_alongship", "angle_athwartship", "angle_sensitivity_alongship",
                    "angle_sensitivity_athwartship", "angle_offset_alongship", "angle_offset_athwartship")


def _encoding(bg: xr.Dataset | None) -> str:
    """"complex" when the beam group holds ``backscatter_i`` (EK80 WBT), else "power"."""
    return "complex" if bg is not None and "backscatter_i" in bg.variables else "power"


def check_echosounder(tree: xr.DataTree, *, source: str = "") -> str:
    """Check a Simrad file echopype converted: every variable calibration needs is present, all
    the missing ones named in one message.

    Parameters
    ----------
    tree : xarray.DataTree
    source : str
        The file (for messages).

    Returns
    -------
    str
        "EK60" or "EK80".

    Raises
    ------
    DatasetError
        Not such a file, or variables missing (every one named, with its group).
    """
    where = source or "dataset"
    model = echosounder_model(tree)
    if model is None:
        raise DatasetError(f"{where}: not a Simrad echosounder file converted by echopype (the root's "
                           f"keywords name none of {', '.join(SIMRAD_MODELS)})")
    bg = group_of(tree, _BG)
    enc = _encoding(bg)
    missing = []
    for group, names in ECHOSOUNDER_NEEDS[enc].items():
        ds = group_of(tree, group)
        missing += [f"/{group}/{n}" for n in names if ds is None or n not in ds.variables]
    if bg is not None and enc == "power" and "beam_type" in bg.variables:
        split = np.asarray(bg["beam_type"].values).ravel() == 1
        if split.any():
            missing += [f"/{_BG}/{n}" for n in SPLIT_BEAM_NEEDS if n not in bg.variables]
    if missing:
        raise DatasetError(f"{where}: an {model} file ({enc} samples) lacks {len(missing)} variable"
                           f"{'s' if len(missing) > 1 else ''} calibration needs: {', '.join(missing)} "
                           f"(as echopype's open_raw(..., sonar_model={model!r}).to_netcdf writes them)")
    dims = tuple(bg["backscatter_r"].dims)
    want = ("channel", "ping_time", "range_sample") + (("beam",) if enc == "complex" else ())
    if dims != want and not (enc == "power" and dims == want + ("beam",)):
        raise DatasetError(f"{where}: /{_BG}/backscatter_r has dims {dims}; a {model} file converted by "
                           f"echopype has {want}")
    return model


def is_power_record(tree: xr.DataTree) -> bool:
    """Whether the dataset is a Simrad file echopype converted, which :func:`read_power_record`
    reads (EK60 power and angles) or refuses by name (EK80)."""
    return echosounder_model(tree) is not None


@dataclass(frozen=True, eq=False)
class PowerRecord:
    """A Simrad power record: what the EK60 calibration needs, per channel and ping.

    Attributes
    ----------
    model : str
        "EK60" or "EK80" (the range shift of the time-varied gain differs).
    channel : ndarray of str, shape (n_channels,)
    ping_time : ndarray of datetime64[ns], shape (n_pings,)
    power_db : ndarray, shape (n_channels, n_pings, n_samples)
        Received power P_r (dB re 1 W); NaN past a ping's last sample.
    sample_interval_s, sound_speed_m_s, absorption_db_per_m, transmit_power_w,
    pulse_duration_s, gain_db, sa_correction_db : ndarray, shape (n_channels, n_pings)
        The settings of each ping; the gain and S_a correction are the calibration's entries
        for the pulse duration transmitted (the nearest ``pulse_length`` of /Vendor_specific).
    frequency_hz, equivalent_beam_angle_db : ndarray, shape (n_channels,)
    source : str
    """

    model: str
    channel: np.ndarray
    ping_time: np.ndarray
    power_db: np.ndarray
    sample_interval_s: np.ndarray
    sound_speed_m_s: np.ndarray
    absorption_db_per_m: np.ndarray
    transmit_power_w: np.ndarray
    pulse_duration_s: np.ndarray
    gain_db: np.ndarray
    sa_correction_db: np.ndarray
    frequency_hz: np.ndarray
    equivalent_beam_angle_db: np.ndarray
    source: str = ""


def _per_ping(var: xr.DataArray, channels, ping_time, where: str) -> np.ndarray:
    """A variable given per channel, per (channel, time) or per (channel, ping_time) as an
    (n_channels, n_pings) array: another time axis (the Environment's ``time1``) is interpolated
    to the ping times, as echopype does (one time: that value)."""
    v = var
    if "channel" in v.dims:
        v = v.sel(channel=channels)
    else:
        v = v.expand_dims(channel=channels)
    times = [d for d in v.dims if d != "channel"]
    n_p = len(ping_time)
    if not times:
        out = np.repeat(np.asarray(v.values, float)[:, None], n_p, axis=1)
    elif times == ["ping_time"]:
        out = np.asarray(v.transpose("channel", "ping_time").values, float)
    elif len(times) == 1:
        t = v[times[0]].values.astype("datetime64[ns]").astype(np.int64).astype(float)
        vals = np.asarray(v.transpose("channel", times[0]).values, float)
        tp = ping_time.astype("datetime64[ns]").astype(np.int64).astype(float)
        out = np.empty((vals.shape[0], n_p))
        for c in range(vals.shape[0]):
            ok = np.isfinite(vals[c])
            if not ok.any():
                raise DatasetError(f"{where}: /{var.name} holds no finite value for channel {channels[c]}")
            out[c] = vals[c, ok][0] if ok.sum() == 1 else np.interp(tp, t[ok], vals[c, ok])
    else:
        raise DatasetError(f"{where}: {var.name} has dims {var.dims}; expected channel and one time axis")
    return out


def read_power_record(tree: xr.DataTree, *, source: str = "") -> PowerRecord:
    """The power record of an EK60 file echopype converted.

    Raises
    ------
    DatasetError
        Missing variables (all named, :func:`check_echosounder`), an EK80 file (its range
        shift and complex samples are echopype's to calibrate: named) or values that are not
        finite where calibration needs them.
    """
    where = source or "dataset"
    model = check_echosounder(tree, source=where)
    bg = group_of(tree, _BG)
    if model != "EK60" or _encoding(bg) != "power":
        what = "complex samples (WBT)" if _encoding(bg) == "complex" else "power samples"
        raise DatasetError(f"{where}: an {model} file of {what}; abacus calibrates EK60 power records "
                           f"(checked against echopype's compute_Sv): give echopype's compute_Sv this file")
    env, vend = group_of(tree, ENVIRONMENT_GROUP), group_of(tree, _VEND)
    channels = np.asarray(bg["channel"].values)
    ping_time = np.asarray(bg["ping_time"].values)
    p = bg["backscatter_r"]
    if "beam" in p.dims:                    # EK80 power: one beam
        p = p.isel(beam=0)
    power = np.asarray(p.transpose("channel", "ping_time", "range_sample").values, float)
    per = {name: _per_ping(bg[name], channels, ping_time, where)
           for name in ("sample_interval", "transmit_power", "transmit_duration_nominal")}
    c = _per_ping(env["sound_speed_indicative"], channels, ping_time, where)
    alpha = _per_ping(env["absorption_indicative"], channels, ping_time, where)
    # the calibration's entry for the pulse transmitted: the nearest pulse_length (echopype's
    # get_vend_cal_params_power)
    plen = np.asarray(vend["pulse_length"].sel(channel=channels).values, float)
    tau = per["transmit_duration_nominal"]
    pick = np.argmin(np.abs(tau[:, :, None] - plen[:, None, :]), axis=2)
    take = {name: np.take_along_axis(np.asarray(vend[name].sel(channel=channels).values, float), pick, axis=1)
            for name in ("gain_correction", "sa_correction")}
    freq = np.asarray(bg["frequency_nominal"].sel(channel=channels).values, float).ravel()
    psi = np.asarray(bg["equivalent_beam_angle"].sel(channel=channels).values, float).ravel()
    for name, a in (("sample_interval", per["sample_interval"]), ("transmit_power", per["transmit_power"]),
                    ("transmit_duration_nominal", tau), ("frequency_nominal", freq)):
        if not np.all(np.isfinite(a) & (a > 0)):
            raise DatasetError(f"{where}: /{_BG}/{name} must be positive and finite for every channel and ping")
    for name, a in (("sound_speed_indicative", c), ("absorption_indicative", alpha)):
        if not np.all(np.isfinite(a)) or np.any(a < 0) or (name.startswith("sound") and np.any(a <= 0)):
            raise DatasetError(f"{where}: /{ENVIRONMENT_GROUP}/{name} must be finite and positive")
    return PowerRecord(model, channels.astype(str), ping_time, power, per["sample_interval"], c, alpha,
                       per["transmit_power"], tau, take["gain_correction"], take["sa_correction"],
                       freq, psi, where)


#: what NaN means in a file echopype converted (its convention: a value the raw file did not hold)
FOREIGN_NAN_MEANS = "not recorded: echopype writes NaN where the raw file holds no value"


def annotate_missing(tree: xr.DataTree) -> xr.DataTree:
    """A copy of a foreign file whose NaN are documented: every float variable holding NaN gets
    ``nan_means`` (:data:`FOREIGN_NAN_MEANS`) unless it has one, so that abacus' writer, which
    refuses unexplained NaN (:func:`processing.base.dataset.check_finite`), writes the file back
    with its values unchanged."""
    from processing.base.dataset import NAN_MEANS
    out = tree.copy()
    for node in out.subtree:
        ds = node.to_dataset(inherit=False)
        changed = False
        for name, var in ds.data_vars.items():
            if var.dtype.kind in "fc" and NAN_MEANS not in var.attrs and var.size \
                    and not np.all(np.isfinite(var.values)):
                ds[name].attrs = {**var.attrs, NAN_MEANS: FOREIGN_NAN_MEANS}
                changed = True
        if changed:
            node.dataset = ds
    return out
