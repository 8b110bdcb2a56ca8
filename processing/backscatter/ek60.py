"""Simrad power records calibrated: received power to Sv, the EK60 way.

The sonar equation for volume backscattering of a Simrad split-beam or single-beam echosounder
(Simrad EK60 Reference Manual, "Calibration" and "Formulae"; MacLennan & Simmonds, *Fisheries
Acoustics*, §2.4; implemented the same way by echopype, ``calibrate/calibrate_ek.py``
``CalibrateEK._cal_power_samples``, and by pyEcholab)::

    Sv = P_r + 20 log10 r' + 2 α r' − 10 log10(P_t λ² c τ ψ G₀² / (32 π²)) − 2 S_a
       = P_r + 20 log10 r' + 2 α r' − [10 log10 P_t + 2 G + Ψ + 10 log10(λ² c τ / (32 π²))] − 2 S_a

P_r the received power (dB re 1 W), P_t the transmitted power (W), G the transducer gain and Ψ the
equivalent two-way beam angle (dB re 1 sr) of the calibration, S_a its correction of the
integrated pulse (the sa_correction), τ the nominal pulse duration, λ = c / f, α the absorption
(dB/m). The range of sample k is r = k Δt c / 2 (echopype's ``echo_range``); the time-varied gain
uses r' = r − Δr_TVG, the EK60's two-sample delay Δr_TVG = 2 · Δt c / 2 (echopype's
``range_mod_TVG_EK``). r' ≤ 0 (the first samples) has no Sv (NaN, as in echopype). EK80 files
(other range shifts, complex samples) are read and checked but left to echopype's calibration.
"""
from __future__ import annotations

import numpy as np

from processing.base.echosounder import PowerRecord

__all__ = ["echo_range_m", "tvg_range_m", "sv_of_power", "CSV_TERMS"]

#: what the constant of the equation is made of (docs)
CSV_TERMS = "10 log10 P_t + 2 G + Ψ + 10 log10(λ² c τ / (32 π²))"


def echo_range_m(record: PowerRecord) -> np.ndarray:
    """r = k Δt c / 2 of every sample (m), shape (n_channels, n_pings, n_samples); NaN where
    the ping holds no sample (P_r NaN)."""
    k = np.arange(record.power_db.shape[2], dtype=float)
    r = k[None, None, :] * (record.sample_interval_s * record.sound_speed_m_s / 2.0)[:, :, None]
    return np.where(np.isfinite(record.power_db), r, np.nan)


def tvg_range_m(record: PowerRecord) -> np.ndarray:
    """r' of the time-varied gain (m), same shape: r less the EK60's two-sample delay."""
    shift = 2.0 * record.sample_interval_s * record.sound_speed_m_s / 2.0
    return echo_range_m(record) - shift[:, :, None]


def sv_of_power(record: PowerRecord) -> tuple:
    """Sv of every sample of a power record.

    Parameters
    ----------
    record : PowerRecord

    Returns
    -------
    sv_db : ndarray, shape (n_channels, n_pings, n_samples)
        Sv (dB re 1 m⁻¹); NaN where r' ≤ 0 or the ping holds no sample.
    echo_range : ndarray, same shape
        r = k Δt c / 2 (m).
    """
    r = echo_range_m(record)
    rt = tvg_range_m(record)
    rt = np.where(rt > 0, rt, np.nan)
    c = record.sound_speed_m_s
    lam = c / record.frequency_hz[:, None]
    csv = (10 * np.log10(record.transmit_power_w) + 2 * record.gain_db
           + record.equivalent_beam_angle_db[:, None]
           + 10 * np.log10(lam**2 * c * record.pulse_duration_s / (32 * np.pi**2)))
    with np.errstate(invalid="ignore", divide="ignore"):
        sv = (record.power_db + 20 * np.log10(rt) + 2 * record.absorption_db_per_m[:, :, None] * rt
              - csv[:, :, None] - 2 * record.sa_correction_db[:, :, None])
    return sv, r
