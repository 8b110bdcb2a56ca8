"""The Doppler bank of the fast synthesis against the exact synthesis (issue 31).

The exact synthesis evaluates every shifted echo A u(s) e^{j2πf s} at every sample; the bank
(acoustics/synthesis/doppler_bank.py) is an interpolation in f whose error the bank measures for
itself. The bound asserted is that target plus the fast synthesis' own floor against ``exact``
(−62 dB at U = 2, L = 8 for the sqrt-Hann pulse: docs/accuracy.md), added as amplitudes.
"""
import numpy as np
import pytest

from acoustics.medium import Medium
from acoustics.sonar import preset
from acoustics.sonar.build import preset_sonar
from acoustics.sonar.pulse import Pulse
from acoustics.synthesis.arrivals import EchoModel
from acoustics.synthesis.doppler_bank import bank_error_db, bank_nodes, bank_weights
from acoustics.synthesis.synthesize import synthesize

from .conftest import on_one_thread_and_all

FAST_FLOOR_DB = -62.0


@pytest.fixture(scope="module")
def model():
    son = preset_sonar()
    return EchoModel(son.transmitter, son.receiver.elements, Medium(preset.SOUND_SPEED_M_S, 0.1),
                     preset.CENTER_FREQUENCY_HZ, preset.ADC_SCALE_COUNTS)


def _scatterers(n, seed=3):
    rng = np.random.default_rng(seed)
    r = rng.uniform(12, 50, n)
    az = rng.uniform(-0.14, 0.14, n)
    el = rng.uniform(-0.02, 0.02, n)
    p = np.column_stack([r * np.cos(el) * np.sin(az), r * np.sin(el), r * np.cos(el) * np.cos(az)])
    q = rng.rayleigh(0.5, n) * np.exp(1j * rng.uniform(-np.pi, np.pi, n))
    return p, q, rng


def _rel_db(y, ref):
    return 20 * np.log10(np.linalg.norm(y - ref) / np.linalg.norm(ref))


def _bound_db(target_db):
    return 20 * np.log10(10 ** (target_db / 20) + 10 ** (FAST_FLOOR_DB / 20))


@pytest.mark.parametrize("target_db", [-40.0, -55.0])
def test_bank_meets_its_error_target_against_the_exact_synthesis(model, target_db):
    p, q, rng = _scatterers(120)
    fd = rng.uniform(-750.0, 300.0, p.shape[0])
    fd[:10] = 0.0                                   # still ones go the unshifted way
    kw = dict(pulse=Pulse(), rate_hz=preset.SAMPLE_RATE_HZ, n_samples=2048, doppler_hz=fd)
    ref = synthesize(model, p, q, method="exact", **kw)
    y = synthesize(model, p, q, doppler_method="bank", doppler_error_db=target_db, **kw)
    assert _rel_db(y, ref) <= _bound_db(target_db)


def test_one_shift_is_a_single_exact_node(model):
    # every echo shifted alike: one node at that shift, no interpolation error at all
    p, q, _ = _scatterers(60)
    fd = np.full(p.shape[0], -420.0)
    assert bank_nodes(Pulse(), 2 * preset.SAMPLE_RATE_HZ, fd, -50.0).size == 1
    kw = dict(pulse=Pulse(), rate_hz=preset.SAMPLE_RATE_HZ, n_samples=2048, doppler_hz=fd)
    ref = synthesize(model, p, q, method="exact", **kw)
    assert _rel_db(synthesize(model, p, q, **kw), ref) <= FAST_FLOOR_DB + 1.0


def test_a_cw_pulse_has_no_coupling_and_still_meets_the_target(model):
    # B = 0: no range–Doppler coupling to take out, the bank interpolates the carrier itself
    pulse = Pulse(bandwidth_hz=0.0, duration_s=0.002, taper="hann")
    p, q, rng = _scatterers(80)
    fd = rng.uniform(-300.0, 300.0, p.shape[0])
    kw = dict(pulse=pulse, rate_hz=preset.SAMPLE_RATE_HZ, n_samples=2048, doppler_hz=fd)
    ref = synthesize(model, p, q, method="exact", **kw)
    y = synthesize(model, p, q, doppler_error_db=-50.0, **kw)
    assert np.all(np.isfinite(y))
    assert _rel_db(y, ref) <= _bound_db(-45.0)


def test_lagrange_weights_sum_to_one_and_select_their_node():
    nodes = np.array([-700.0, -350.0, 0.0, 200.0])
    w = bank_weights(np.concatenate([nodes, np.linspace(-700, 200, 13)]), nodes)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)   # interpolates constants exactly
    np.testing.assert_allclose(w[:4], np.eye(4), atol=1e-15)


def test_more_nodes_never_worse_over_the_same_shifts():
    e = [bank_error_db(Pulse(), 2 * preset.SAMPLE_RATE_HZ, -750.0, 750.0, n) for n in (2, 3, 5, 8)]
    assert all(b <= a + 0.5 for a, b in zip(e, e[1:]))
    assert e[-1] < -50.0


def test_bank_is_bit_identical_for_any_thread_count(model):
    p, q, rng = _scatterers(700)
    fd = rng.uniform(-700.0, 0.0, p.shape[0])
    kw = dict(pulse=Pulse(), rate_hz=preset.SAMPLE_RATE_HZ, n_samples=2048, doppler_hz=fd)
    one, many = on_one_thread_and_all(lambda: synthesize(model, p, q, **kw))
    assert np.array_equal(one, many)


def test_a_school_in_a_short_stretch_of_the_record_beside_still_echoes(model):
    # the shifted echoes within 20–24 m (the bank convolves that stretch alone), still ones
    # over the whole record (the plain replica): both under one inverse FFT, as exact
    p, q, rng = _scatterers(240, seed=11)
    r = np.linalg.norm(p, axis=1)
    school = rng.uniform(20.0, 24.0, 120)
    p[:120] *= (school / r[:120])[:, None]
    fd = np.zeros(p.shape[0])
    fd[:120] = rng.uniform(-500.0, -100.0, 120)
    kw = dict(pulse=Pulse(), rate_hz=preset.SAMPLE_RATE_HZ, n_samples=4096, doppler_hz=fd)
    ref = synthesize(model, p, q, method="exact", **kw)
    assert _rel_db(synthesize(model, p, q, **kw), ref) <= _bound_db(-50.0)
