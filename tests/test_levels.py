"""Physical levels: the echo of a known TS and the sea's noise, in counts, as the sonar equation
says (each number recomputed here from the textbook formulas, not from the code's)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import acoustics
import processing
from acoustics.scene import SceneWarning, scene_from_text

SL, M, G, VFS, BITS = 210.0, -180.0, 50.0, 1.0, 12


def scene(text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return scene_from_text("name: levels\nsonar:\n  levels: {source_level_db: 210, "
                               "receive_sensitivity_db: -180, receiver_gain_db: 50, adc_full_scale_v: 1.0}\n"
                               + text)


def test_a_known_ts_echoes_at_the_sonar_equation_level():
    """EL = SL − 2 (20 log r + α r) + TS at the element (on axis), in volts M·G, in counts
    2^(bits−1)/V_fs; the calibrated image peak is that amplitude (docs/conventions.md)."""
    r, ts = 20.0, -40.0
    sc = scene(f"targets:\n  points:\n    - {{range_m: {r}, azimuth_deg: 0, elevation_deg: 0, "
               f"backscatter: {{model: fixed, ts_db: {ts}}}}}\n")
    alpha = sc.medium.absorption_db_per_m
    el_db = SL - 2 * (20 * math.log10(r) + alpha * r) + ts                  # dB re 1 µPa
    counts = 10 ** (el_db / 20) * 10 ** ((M + G) / 20) * 2 ** (BITS - 1) / VFS
    im = processing.images_of(processing.image(acoustics.simulate(sc)))
    peak = np.abs(im.image[0, 0]).max()
    assert 20 * math.log10(peak / counts) == pytest.approx(0.0, abs=0.3)


def test_sea_noise_is_thermal_noise_through_one_element():
    """σ per quadrature = √((10^((NL − DI)/10) M² + e_n²) B / 2) G 2^(bits−1)/V_fs, NL = −15 +
    20 log f_kHz (Mellen), DI = 10 log(4π w h/λ²) of a 12 x 20 mm element; measured on 4096 x 16
    samples (standard error 0.4 %)."""
    sc = scene("noise: {enabled: true, model: sea, system_noise_nv_per_sqrt_hz: 1.0}\n")
    f0 = sc.signal.center_frequency_hz
    lam = sc.medium.sound_speed_m_s / f0
    nl = -15 + 20 * math.log10(f0 / 1e3) - 10 * math.log10(4 * math.pi * 0.012 * 0.020 / lam**2)
    v2 = (10 ** (nl / 10) * 10 ** (M / 10) + (1e-9) ** 2) * sc.noise.bandwidth_hz
    sigma = math.sqrt(v2 / 2) * 10 ** (G / 20) * 2 ** (BITS - 1) / VFS
    tree = acoustics.simulate(sc, pings=range(2))
    x = tree["Sonar/Beam_group1"]["backscatter_r"].values
    assert np.std(x) == pytest.approx(sigma, rel=0.02)


def test_sea_noise_needs_levels():
    with pytest.raises(acoustics.SceneError, match="needs sonar.levels"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SceneWarning)
            scene_from_text("name: x\nnoise: {enabled: true, model: sea}\n")
