"""Physical levels: source level, receiver sensitivity and gain, the sea's noise — in counts.

By default abacus works in the thesis' units: a unit-driven transmit element gives pressure 1
at 1 m, k = ``sampling.adc.scale_counts`` ADC counts per unit of pressure, and the noise is a
given σ in counts (docs/conventions.md). A scene with ``sonar.levels`` states instead what a
real sonar has, and both numbers follow:

* the transmitter's on-axis source level SL (dB re 1 µPa at 1 m) fixes the pressure unit: the
  S unit-driven elements give SL, so one unit is 10^(SL/20) / S µPa;
* a receive element of sensitivity M (dB re 1 V/µPa), a receiver gain G (dB) and an ADC whose
  full scale V_fs (V) is 2^(bits−1) counts turn µPa into counts:
  k = 10^(SL/20)/S · 10^((M + G)/20) · 2^(bits−1)/V_fs  (counts per unit);
* with ``noise.model: sea`` the noise is the sea's thermal noise (Mellen 1952:
  NL = −15 + 20 log10 f_kHz dB re 1 µPa²/Hz; at 420 kHz it exceeds wind noise of any sea state
  on the Wenz curves) received by one element of directivity index DI = 10 log10(4π w h / λ²)
  (a baffled piston, w, h ≫ λ/2), plus the receiver's own input noise e_n (V/√Hz), over the
  noise band B: σ (counts, per quadrature component) = √((10^((NL − DI)/10) M² + e_n²) B / 2)
  · 10^(G/20) · 2^(bits−1)/V_fs.

So SNR = SL − 2 TL + TS − (NL − DI + 10 log10 B) follows from the physics and not from a chosen σ;
the gain and the ADC only set where in the counts it lies (and whether the ADC clips).
The thesis gives no source level or sensitivity for ABACUS; the defaults are those of a typical
420 kHz fisheries transducer (SL 210 dB re 1 µPa at 1 m, M −180 dB re 1 V/µPa) and say so.
"""
from __future__ import annotations

import math

__all__ = ["mellen_thermal_noise_db", "piston_directivity_index_db", "counts_per_unit",
           "sea_noise_sigma_counts", "transmit_weight_sum"]


def mellen_thermal_noise_db(frequency_hz: float) -> float:
    """Thermal noise spectrum level (dB re 1 µPa²/Hz) of sea water (Mellen 1952)."""
    return -15.0 + 20.0 * math.log10(frequency_hz / 1e3)


def piston_directivity_index_db(width_m: float, height_m: float, wavelength_m: float) -> float:
    """DI (dB) of a baffled rectangular piston much larger than λ/2: 10 log10(4π w h / λ²)."""
    return 10.0 * math.log10(4.0 * math.pi * width_m * height_m / wavelength_m**2)


def transmit_weight_sum(son) -> float:
    """S = Σ w of the transmitter's elements, from a scene's ``sonar`` section (no arrays built)."""
    if son.preset == "abacus":
        from acoustics.sonar import preset
        return float(preset.ELEMENTS_PER_ARRAY)
    tx = son.transmitter
    if tx.line is not None:
        return float(tx.line.count)
    return float(sum(e.weight for e in tx.elements))


def counts_per_unit(levels, *, weight_sum: float, bits: int) -> float:
    """k (ADC counts per unit of the simulator's pressure) of physical ``levels``."""
    unit_upa = 10.0 ** (levels.source_level_db / 20.0) / weight_sum
    volts_per_upa = 10.0 ** ((levels.receive_sensitivity_db + levels.receiver_gain_db) / 20.0)
    return unit_upa * volts_per_upa * 2.0 ** (bits - 1) / levels.adc_full_scale_v


def sea_noise_sigma_counts(levels, *, frequency_hz: float, wavelength_m: float, element_m,
                           band_hz: float, bits: int, system_noise_v_per_sqrt_hz: float) -> float:
    """σ (counts, per quadrature component) of thermal sea noise plus receiver noise."""
    di = piston_directivity_index_db(element_m[0], element_m[1], wavelength_m)
    nl = mellen_thermal_noise_db(frequency_hz) - di                   # dB re 1 µPa²/Hz
    m = 10.0 ** (levels.receive_sensitivity_db / 20.0)                # V/µPa
    v2 = (10.0 ** (nl / 10.0) * m * m + system_noise_v_per_sqrt_hz**2) * band_hz
    gain = 10.0 ** (levels.receiver_gain_db / 20.0)
    return math.sqrt(v2 / 2.0) * gain * 2.0 ** (bits - 1) / levels.adc_full_scale_v
