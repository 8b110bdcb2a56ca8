"""abacus' calibrated image as echopype calibrates a Simrad EK60: the documented conversion that
lets echopype's ``compute_Sv`` (and its MVBS) run on abacus' Sv.

echopype opens abacus' own datasets, prints their repr and combines them (their /Processing
products lie flat in /Vendor_specific in the file: processing/base/file_layout.py), but it
calibrates only the sonars it knows (its ``compute_Sv`` looks the root's ``keywords`` up among
EK60, EK80, AZFP, ...: ``KeyError 'ABACUS'`` otherwise) and appends no product of processing.
The view writes what ABACUS measured in the EK60's terms instead:

* one **channel per beam** of the image (subarray A by default), its samples the image's range
  cells, ``sample_interval`` = 2 Δr / c;
* the EK60 calibration (:mod:`processing.backscatter.ek60`) chosen so that echopype's equation
  *is* abacus' sonar equation (processing/backscatter/calibration.py):
  the equivalent beam angle Ψ = 10 log10 Ψ_b (the beam's two-way equivalent solid angle), the
  pulse duration τ = 2 L_r / c (so that c τ / 2 is the compressed pulse's range extent L_r),
  P_t = 1 W, the gain G₀ = 4π G / λ (G the image's calibration gain, counts m; 10 log10 G₀ dB),
  S_a = 0 (then P_t G₀² λ² c τ ψ / (32π²) = G² L_r Ψ_b, abacus' denominator);
* ``backscatter_r`` = Sv − 20 log10 r' − 2 α r' + C_Sv: the received power (dB re 1 count²,
  noise subtracted) referred to the view's sample ranges, so that echopype's ``compute_Sv``
  returns abacus' Sv of every cell to rounding; cells of noise only (s_v ≤ 0 after noise
  subtraction: no Sv in dB) are NaN — average the linear ``s_v`` abacus exports beside Sv
  (``abacus sv --cells``), never these dB values.

The per-element samples, the ground truth and /Processing stay in the abacus dataset.
"""
from __future__ import annotations

import datetime as _dt

import numpy as np
import xarray as xr

from processing.base.contract import ELEMENT_GROUP, SONAR_GROUP, SV_GROUP
from processing.base.dataset import DatasetError, as_tree, group_of, source_of

__all__ = ["echopype_view", "VIEW_SONAR_MODEL"]

#: the root's ``keywords`` of the view: the calibration echopype applies
VIEW_SONAR_MODEL = "EK60"


def echopype_view(tree, settings=None, *, image_group: str | None = None) -> xr.DataTree:
    """The EK60-convention view of a dataset's calibrated image (module docstring).

    Parameters
    ----------
    tree : xarray.DataTree or path
        A dataset with samples and a calibration; its /Processing/Sv is used when it holds every
        cell (``processing.sv(..., cells=True)``), else Sv is computed here.
    settings : optional
        Processing settings (as :func:`processing.sv` takes them).
    image_group : str, optional
        The subarray whose image is exported (default: the detector's).

    Returns
    -------
    xarray.DataTree
        Groups /, /Environment, /Platform, /Platform/NMEA, /Provenance, /Sonar,
        /Sonar/Beam_group1 and /Vendor_specific as echopype's EK60 converter lays them out.

    Raises
    ------
    DatasetError
        No calibration, or a Simrad record (already echopype's).
    """
    from processing.backscatter.sv import backscatter
    tree = as_tree(tree)
    sv_ds = group_of(tree, SV_GROUP)
    if sv_ds is None or "Sv" not in sv_ds or "solid_angle_sr" not in sv_ds or (
            image_group is not None and sv_ds.attrs.get("image_group") != image_group):
        sv_ds = backscatter(tree, settings, image_group=image_group, cells=True)[SV_GROUP].to_dataset()
    if "solid_angle_sr" not in sv_ds:
        raise DatasetError(f"{source_of(tree)}: a Simrad record; echopype opens it as it is")
    sv = np.asarray(sv_ds["Sv"].values, float)                           # (ping, cell, beam)
    r = np.asarray(sv_ds["cell_range_m"].values, float)[0, :, 0]
    a = sv_ds.attrs
    c, f0 = float(a["sound_speed_m_s"]), float(a["center_frequency_hz"])
    alpha, gain = float(a["absorption_db_per_m"]), float(a["calibration_gain_counts_m"])
    lam = c / f0
    dr = float(np.median(np.diff(r)))
    dt = 2.0 * dr / c
    # sample k at echo_range k Δr: the cells keep their ranges (to Δr/2), so echopype's MVBS bins
    # them where abacus does; the EK60's two-sample TVG delay (r' = (k − 2) Δr) is folded into
    # backscatter_r below, so Sv comes back exactly
    n0 = max(int(round(r[0] / dr)), 0)
    n_p, n_c, n_b = sv.shape
    k = n0 + np.arange(n_c)
    r_tvg = (k - 2) * dt * c / 2.0                                       # r' of each exported sample
    r_tvg = np.where(r_tvg > 0, r_tvg, np.nan)                          # echopype: no Sv where r' <= 0
    tau = 2.0 * float(a["range_energy_width_m"]) / c
    psi_db = 10 * np.log10(np.asarray(sv_ds["solid_angle_sr"].values, float))
    g0_db = 10 * np.log10(4 * np.pi * gain / lam)      # gain_correction (dB): G₀ = 4π G / λ
    csv = 2 * g0_db + psi_db + 10 * np.log10(lam**2 * c * tau / (32 * np.pi**2))      # (beam,), P_t = 1 W
    power = np.full((n_b, n_p, n0 + n_c), np.nan)
    power[:, :, n0:] = (sv - 20 * np.log10(r_tvg)[None, :, None] - 2 * alpha * r_tvg[None, :, None]
                        + csv[None, None, :]).transpose(2, 0, 1)
    angles = np.asarray(sv_ds["beam_angle_deg"].values, float)
    group = str(a.get("image_group", ""))
    channels = np.array([f"abacus {group} beam {i:03d} {th:+.2f} deg" for i, th in enumerate(angles)])
    eg = tree[ELEMENT_GROUP].ds
    ping_time = np.asarray(eg["ping_time"].values).astype("datetime64[ns]")
    per = lambda v: (("channel", "ping_time"), np.full((n_b, n_p), float(v)))   # noqa: E731
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    beam = xr.Dataset(
        {"backscatter_r": (("channel", "ping_time", "range_sample"), power,
                           {"long_name": "received power, noise subtracted, referred to the sample's range",
                            "units": "dB re 1 count^2 (as W)",
                            "nan_means": "no Sv: before the image's first range, or noise only (s_v <= 0)"}),
         "frequency_nominal": ("channel", np.full(n_b, f0), {"units": "Hz"}),
         "beam_type": ("channel", np.zeros(n_b, int)),
         "equivalent_beam_angle": ("channel", psi_db, {"units": "dB re 1 sr"}),
         "gain_correction": ("channel", np.full(n_b, g0_db), {"units": "dB"}),
         **{f"angle_{w}_{s}": ("channel", np.zeros(n_b)) for w in ("offset", "sensitivity")
            for s in ("alongship", "athwartship")},
         **{f"beamwidth_twoway_{s}": ("channel", np.full(n_b, np.nan),
                                     {"units": "arc_degree", "nan_means": "not an EK60 beam: see Ψ"})
            for s in ("alongship", "athwartship")},
         "beam_direction_x": ("channel", np.sin(np.radians(angles))),
         "beam_direction_y": ("channel", np.zeros(n_b)),
         "beam_direction_z": ("channel", np.cos(np.radians(angles))),
         "sample_interval": per(dt), "transmit_power": per(1.0), "transmit_duration_nominal": per(tau),
         "transmit_bandwidth": per(float(group_of(tree, SONAR_GROUP)["transmit_bandwidth"].values)),
         "sample_time_offset": per(0.0), "channel_mode": per(0.0),
         "transmit_frequency_start": ("channel", np.full(n_b, f0)),
         "transmit_frequency_stop": ("channel", np.full(n_b, f0))},
        coords={"channel": channels, "ping_time": ping_time, "range_sample": np.arange(n0 + n_c)},
        attrs={"beam_mode": "vertical", "conversion_equation_t": "type_3"})
    env = xr.Dataset({"absorption_indicative": (("channel", "time1"), np.full((n_b, 1), alpha), {"units": "dB/m"}),
                      "sound_speed_indicative": (("channel", "time1"), np.full((n_b, 1), c), {"units": "m/s"}),
                      "frequency_nominal": ("channel", np.full(n_b, f0))},
                     coords={"channel": channels, "time1": ping_time[:1]})
    vend = xr.Dataset({"frequency_nominal": ("channel", np.full(n_b, f0)),
                       "gain_correction": (("channel", "pulse_length_bin"), np.full((n_b, 1), g0_db)),
                       "sa_correction": (("channel", "pulse_length_bin"), np.zeros((n_b, 1))),
                       "pulse_length": (("channel", "pulse_length_bin"), np.full((n_b, 1), tau))},
                      coords={"channel": channels, "pulse_length_bin": [0]})
    src = source_of(tree)
    root = {"conventions": "CF-1.7, SONAR-netCDF4-1.0, ACDD-1.3", "keywords": VIEW_SONAR_MODEL,
            "sonar_convention_authority": "ICES", "sonar_convention_name": "SONAR-netCDF4",
            "sonar_convention_version": "1.0",
            "title": f"abacus: the calibrated image of subarray {group} of {src} in the EK60's convention",
            "summary": ("one channel per beam of abacus' image; calibration chosen so that echopype's EK60 "
                        "equation returns abacus' Sv (processing/backscatter/echopype_view.py); noise-only "
                        "cells NaN: average abacus' linear s_v"),
            "date_created": now}
    groups = {
        "/": xr.Dataset(attrs=root),
        "/Environment": env,
        "/Platform": xr.Dataset({f"transducer_offset_{x}": ("channel", np.zeros(n_b), {"units": "m"})
                                 for x in "xyz"}, coords={"channel": channels},
                                attrs={"platform_name": "", "platform_type": ""}),
        # echopype tells a converted Simrad file by Platform/NMEA's nmea_time and combines files
        # by their first times: one empty datagram per ping (no GPS)
        "/Platform/NMEA": xr.Dataset({"NMEA_datagram": ("nmea_time", np.full(n_p, ""))},
                                     coords={"nmea_time": ping_time}),
        "/Provenance": xr.Dataset({"source_filenames": ("filenames", [src])}, coords={"filenames": [0]},
                                  attrs={"conversion_software_name": "abacus",
                                         "conversion_software_version": _version(),
                                         "conversion_time": now}),
        "/Sonar": xr.Dataset({"beam_group_descr": ("beam_group", [
            "abacus' calibrated image: one channel per beam, Sv by the EK60 equation"])},
            coords={"beam_group": ["Beam_group1"]},
            attrs={"sonar_manufacturer": "abacus", "sonar_model": "ABACUS", "sonar_serial_number": "",
                   "sonar_software_name": "abacus", "sonar_software_version": _version(),
                   "sonar_type": "multibeam"}),
        "/Sonar/Beam_group1": beam,
        "/Vendor_specific": vend,
    }
    return xr.DataTree.from_dict(groups)


def _version() -> str:
    from processing.base.lazy import distribution_version
    return distribution_version("abacus")
