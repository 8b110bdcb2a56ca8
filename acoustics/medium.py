"""The propagation medium: sound speed, absorption, spherical spreading.

Absorption follows Francois & Garrison (1982), "Sound absorption based on ocean
measurements. Part II: Boric acid contribution and equation for total absorption",
J. Acoust. Soc. Am. 72(6), 1879–1890. Sound speed, when not given, follows Mackenzie
(1981), "Nine-term equation for sound speed in the oceans", J. Acoust. Soc. Am. 70(3),
807–812 (check value 1550.744 m/s at 25 °C, 35 PSU, 1000 m).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acoustics.sonar import preset

__all__ = ["Medium", "francois_garrison_db_per_m", "mackenzie_sound_speed_m_s"]


def mackenzie_sound_speed_m_s(temperature_c, salinity_psu, depth_m):
    """Sound speed (m/s) by Mackenzie's nine-term equation (valid 2–30 °C, 25–40 PSU, 0–8000 m)."""
    t, s, d = (np.asarray(a, float) for a in (temperature_c, salinity_psu, depth_m))
    return (1448.96 + 4.591 * t - 5.304e-2 * t**2 + 2.374e-4 * t**3 + 1.340 * (s - 35)
            + 1.630e-2 * d + 1.675e-7 * d**2 - 1.025e-2 * t * (s - 35) - 7.139e-13 * t * d**3)


def francois_garrison_db_per_m(frequency_hz, temperature_c, salinity_psu, depth_m, ph,
                               sound_speed_m_s=None):
    """Absorption coefficient α (dB/m) of sea water by Francois & Garrison (1982).

    Parameters
    ----------
    frequency_hz : array_like
        Frequency (Hz).
    temperature_c, salinity_psu, depth_m, ph : float or array_like
        Temperature (°C), salinity (PSU), depth (m) and pH.
    sound_speed_m_s : float, optional
        Sound speed (m/s); by default F&G's own c = 1412 + 3.21T + 1.19S + 0.0167D.

    Returns
    -------
    ndarray
        α in dB/m (broadcast shape of the inputs).
    """
    f = np.asarray(frequency_hz, float) / 1e3  # the formula is in kHz and dB/km
    t, s, d, ph = (np.asarray(a, float) for a in (temperature_c, salinity_psu, depth_m, ph))
    c = 1412.0 + 3.21 * t + 1.19 * s + 0.0167 * d if sound_speed_m_s is None else np.asarray(sound_speed_m_s, float)
    tk = t + 273.0
    # boric acid
    a1 = 8.86 / c * 10.0 ** (0.78 * ph - 5.0)
    f1 = 2.8 * np.sqrt(s / 35.0) * 10.0 ** (4.0 - 1245.0 / tk)
    # magnesium sulphate
    a2 = 21.44 * s / c * (1.0 + 0.025 * t)
    p2 = 1.0 - 1.37e-4 * d + 6.2e-9 * d**2
    f2 = 8.17 * 10.0 ** (8.0 - 1990.0 / tk) / (1.0 + 0.0018 * (s - 35.0))
    # pure water
    a3 = np.where(t <= 20.0,
                  4.937e-4 - 2.59e-5 * t + 9.11e-7 * t**2 - 1.50e-8 * t**3,
                  3.964e-4 - 1.146e-5 * t + 1.45e-7 * t**2 - 6.5e-10 * t**3)
    p3 = 1.0 - 3.83e-5 * d + 4.9e-10 * d**2
    f2sq = f * f
    alpha_db_km = (a1 * f1 * f2sq / (f2sq + f1 * f1) + a2 * p2 * f2 * f2sq / (f2sq + f2 * f2)
                   + a3 * p3 * f2sq)
    return alpha_db_km / 1e3


@dataclass(frozen=True)
class Medium:
    """A homogeneous medium: constant sound speed and absorption at the carrier.

    Attributes
    ----------
    sound_speed_m_s : float
        c (m/s).
    absorption_db_per_m : float
        α (dB/m) at the centre frequency; pressure falls as 10^(-α r / 20).
    temperature_c, salinity_psu, depth_m, ph : float
        Environment the numbers came from (recorded in datasets).
    """

    sound_speed_m_s: float = preset.SOUND_SPEED_M_S
    absorption_db_per_m: float = 0.0
    temperature_c: float = 10.0
    salinity_psu: float = 35.0
    depth_m: float = 20.0
    ph: float = 8.0

    @classmethod
    def from_spec(cls, spec) -> "Medium":
        """From a resolved scene ``medium`` section (absorption already computed)."""
        return cls(sound_speed_m_s=float(spec.sound_speed_m_s),
                   absorption_db_per_m=float(spec.absorption_db_per_m or 0.0),
                   temperature_c=spec.temperature_c, salinity_psu=spec.salinity_psu,
                   depth_m=spec.depth_m, ph=spec.ph)

    def wavelength_m(self, frequency_hz: float) -> float:
        return self.sound_speed_m_s / frequency_hz

    def wavenumber_rad_m(self, frequency_hz: float) -> float:
        return 2.0 * np.pi * frequency_hz / self.sound_speed_m_s

    def one_way_gain(self, range_m, *, spreading: bool = True, absorption: bool = True):
        """Pressure amplitude factor over one leg: (1/r) 10^(-α r/20), dimensionless per metre.

        Parameters
        ----------
        range_m : array_like
            Leg length (m), > 0.

        Returns
        -------
        ndarray
            Same shape as ``range_m``. Ranges below 1 mm are clamped to 1 mm so a
            scatterer on a transducer face gives a large but finite echo.
        """
        r = np.maximum(np.asarray(range_m, float), 1e-3)
        g = np.ones_like(r)
        if spreading:
            g = g / r
        if absorption and self.absorption_db_per_m:
            g = g * 10.0 ** (-self.absorption_db_per_m * r / 20.0)
        return g
