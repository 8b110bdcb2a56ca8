"""Calibrated colour scales for the figures: an image cell in Sv (dB re 1 m⁻¹) or in TS
(dB re 1 m²), as a fisheries acoustician reads an echogram.

The sonar's calibration (/Sonar, :mod:`processing.backscatter.calibration`) gives G, the image
peak of a 1 m backscatter amplitude at 1 m on the transmit axis, and the absorption α. With the
processing's own share — L_r, the range extent of the compressed pulse's intensity, and Ψ_b, each
beam's two-way equivalent solid angle — a cell of magnitude |I| at range r reads

    Sv = 10 log10 s_v,   s_v = |I|² r² 10^(α r / 5) / (G² L_r Ψ_b)      (dB re 1 m⁻¹; "20 log r" TVG)
    TS = 20 log10(|I| r² 10^(α r / 10) / G)                            (dB re 1 m²; "40 log r" TVG)

(:func:`processing.backscatter.sv.sv_cells`; :func:`processing.backscatter.target_strength.
target_strength_db`). The TS of a cell is the TS a point target on the transmit axis would need to
give that cell — uncompensated for the beam pattern, as a TS echogram is; at a detection's peak
it is the table's ``ts_uncomp``. Neither subtracts the noise (a displayed echogram never does).
A dataset without a calibration is drawn in dB re the image's maximum and says so.
"""
from __future__ import annotations

import numpy as np

__all__ = ["echogram_calibration", "sv_image_db", "ts_image_db", "SV_LABEL", "TS_LABEL",
           "UNCALIBRATED_LABEL", "colour_span_db"]

SV_LABEL = "Sv (dB re 1 m⁻¹)"
TS_LABEL = "TS, uncompensated (dB re 1 m²)"
UNCALIBRATED_LABEL = "|I| (dB re max; the dataset has no calibration)"


def echogram_calibration(tree, images) -> dict | None:
    """The calibration of ``images``' cells, as plain numbers (cheap to send to another process).

    Parameters
    ----------
    tree : xarray.DataTree
        The dataset the images were formed from (its /Sonar calibration and its record).
    images : processing.imaging.images.Images
        Gives the image groups, the beams and the settings (windows) the images were formed with.

    Returns
    -------
    dict or None
        ``gain_counts_m`` (G, counts·m), ``absorption_db_per_m`` (α), ``range_width_m`` (L_r, m),
        ``solid_angle_sr`` (n_groups, n_beams) (Ψ_b per image group, sr); None where the dataset
        carries no calibration (then figures are drawn in dB re max).
    """
    from processing.backscatter.calibration import (beam_solid_angle_sr, calibration_of,
                                                    range_energy_width_m)
    from processing.base.dataset import DatasetError, read_record
    from processing.imaging.beamforming import SubarrayGeometry
    from processing.imaging.compression import RangeFilter
    try:
        cal = calibration_of(tree)
        rec = read_record(tree)
        st = images.settings
        rf = RangeFilter.design(rec.replica, n_samples=rec.samples.shape[-1], rate_hz=rec.rate_hz,
                                bandwidth_hz=rec.bandwidth_hz, range_window=st.range_window)
        groups = rec.image_groups
        psi = np.array([beam_solid_angle_sr(cal, SubarrayGeometry(rec.element_position_m[groups[g]],
                                                                   st.spatial_window),
                                            images.beam_angle_rad, rec.wavelength_m)
                        for g in images.groups])
    except (DatasetError, KeyError, ValueError):
        return None         # no (usable) calibration: the figures say dB re max
    if not (np.isfinite(cal.gain_counts_m) and cal.gain_counts_m > 0 and np.all(psi > 0)):
        return None
    return {"gain_counts_m": float(cal.gain_counts_m),
            "absorption_db_per_m": float(cal.absorption_db_per_m),
            "range_width_m": range_energy_width_m(rf, rec.sound_speed_m_s),
            "solid_angle_sr": psi}


def sv_image_db(magnitude, range_m, calibration: dict, group: int = 0) -> np.ndarray:
    """Sv of every cell of one image.

    Parameters
    ----------
    magnitude : array_like, shape (n_range, n_beams)
        |I| (counts).
    range_m : array_like, shape (n_range,)
    calibration : dict
        From :func:`echogram_calibration`.
    group : int
        Index of the image group (its Ψ_b).

    Returns
    -------
    ndarray, shape (n_range, n_beams)
        Sv (dB re 1 m⁻¹); NaN where |I| = 0.
    """
    from processing.backscatter.sv import sv_cells, sv_db
    s_v = sv_cells(np.asarray(magnitude, float)[None], range_m,
                   gain_counts_m=calibration["gain_counts_m"],
                   absorption_db_per_m=calibration["absorption_db_per_m"],
                   range_width_m=calibration["range_width_m"],
                   solid_angle_sr=calibration["solid_angle_sr"][group])[0]
    return sv_db(s_v)


def ts_image_db(magnitude, range_m, calibration: dict) -> np.ndarray:
    """Uncompensated TS of every cell (or of detections' peaks): the on-axis TS whose echo
    peaks at |I| at that range.

    Parameters
    ----------
    magnitude : array_like, shape (n_range, n_beams) or (n,)
        |I| (counts).
    range_m : array_like, shape (n_range,) (or (n,) for peaks)
    calibration : dict
        From :func:`echogram_calibration` (G and α).

    Returns
    -------
    ndarray, same shape as ``magnitude``
        TS (dB re 1 m²); NaN where |I| = 0.
    """
    mag = np.asarray(magnitude, float)
    r = np.asarray(range_m, float)
    r = r[:, None] if mag.ndim == 2 else r
    rho = mag * r * r * 10.0 ** (calibration["absorption_db_per_m"] * r / 10.0) / calibration["gain_counts_m"]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(rho > 0, 20.0 * np.log10(np.where(rho > 0, rho, 1.0)), np.nan)


def colour_span_db(values_db, dynamic_range_db: float = 40.0, step_db: float = 5.0):
    """(vmin, vmax) of a calibrated colour scale: the top at the brightest cell rounded up to
    ``step_db`` (so that pings drawn alike share round limits), ``dynamic_range_db`` below it."""
    v = np.asarray(values_db, float)
    top = float(np.nanmax(v)) if np.isfinite(v).any() else 0.0
    vmax = step_db * np.ceil(top / step_db)
    return vmax - dynamic_range_db, vmax
