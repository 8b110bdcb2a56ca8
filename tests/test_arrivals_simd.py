"""The far-field spread's vector step (acoustics/synthesis/simd.py) against plain arithmetic.

The spread puts each arrival (τ, A) on its channel's fine grid as the tabulated Kaiser-sinc
kernel, linearly interpolated between table rows: taps k_j = T[r, j] + w ΔT[r, j] on samples
floor(μ) − L/2 + 1 + j, μ = (τ − t0) fs + q0. The reference below does that in numpy, one
arrival at a time, from the (τ, A) that :func:`arrivals` returns; the compiled spread (eight taps
a vector step, four channels a thread taken in turns) must give the same trains to rounding.
"""
import numba
import numpy as np
import pytest

from acoustics.medium import Medium
from acoustics.sonar import preset
from acoustics.sonar.build import preset_sonar
from acoustics.synthesis.arrivals import EchoModel, arrivals, spread_arrivals
from acoustics.synthesis.simd import spread8
from acoustics.synthesis.synthesize import fractional_delay_table

from .conftest import on_one_thread_and_all


def _model(n_rx):
    son = preset_sonar()
    # a channel count that is not a multiple of the four a thread interleaves
    return EchoModel(son.transmitter, son.receiver.elements.subset(np.arange(n_rx)),
                     Medium(preset.SOUND_SPEED_M_S, 0.1), preset.CENTER_FREQUENCY_HZ, 1.0)


def _scatterers(n, seed=5):
    rng = np.random.default_rng(seed)
    r = rng.uniform(11, 40, n)
    az = rng.uniform(-0.14, 0.14, n)
    p = np.column_stack([r * np.sin(az), rng.uniform(-0.5, 0.5, n), r * np.cos(az)])
    q = rng.rayleigh(0.5, n) * np.exp(1j * rng.uniform(-np.pi, np.pi, n))
    return p, q


def _reference_trains(tau, amp, table, t0, fs, q0, n_out):
    """numpy: each arrival's interpolated kernel, added at its samples."""
    n_phase = table.shape[0] - 1
    taps = table.shape[1]
    half = taps // 2
    dtable = np.diff(table, axis=0)
    out = np.zeros((tau.shape[1], n_out), complex)
    mu = (tau - t0) * fs + q0
    for n in range(tau.shape[1]):
        for s in range(tau.shape[0]):
            m = mu[s, n]
            if m < half or m >= n_out - half:
                continue
            m0 = int(m)
            x = (m - m0) * n_phase
            r = min(int(x), n_phase - 1)
            k = table[r] + (x - r) * dtable[r]
            out[n, m0 - half + 1:m0 + half + 1] += amp[s, n] * k
    return out


@pytest.mark.parametrize("taps, n_rx", [(8, 13), (16, 6)])
def test_vector_spread_is_the_interpolated_kernel_at_each_delay(taps, n_rx):
    model = _model(n_rx)
    p, q = _scatterers(400)
    fs, t0, q0 = 90910.0, 0.0, 40
    n_out = 5000
    table = fractional_delay_table(taps, 0.4)
    tau, amp = arrivals(model, p, q)
    ref = _reference_trains(tau, amp, table, t0, fs, q0, n_out)
    got = spread_arrivals(model, p, q, table=table, t0_s=t0, rate_hz=fs, q0=q0, n_out=n_out)
    assert got.shape == ref.shape
    # float64 sums of ~100 arrivals per sample, each rounded differently (fused multiply-adds
    # here, separate products in numpy): agreement to ~1e-13 of the largest sample
    assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref))
    assert np.max(np.abs(ref)) > 0


def test_vector_spread_does_not_depend_on_thread_count():
    model = _model(13)
    p, q = _scatterers(3000, seed=9)
    kw = dict(table=fractional_delay_table(8, 0.4), t0_s=0.0, rate_hz=90910.0, q0=40, n_out=5000)
    one, many = on_one_thread_and_all(lambda: spread_arrivals(model, p, q, **kw))
    assert one.tobytes() == many.tobytes()


@numba.njit
def _one_step(table, dtable, row, w, rre, rim, base, ar, ai):
    spread8(table, dtable, row, w, rre, rim, base, ar, ai)


def test_spread8_adds_eight_interpolated_taps_and_nothing_else():
    rng = np.random.default_rng(1)
    table, dtable = rng.standard_normal(64), rng.standard_normal(64)
    rre, rim = rng.standard_normal(30), rng.standard_normal(30)
    w, ar, ai = 0.37, 1.5, -0.25
    k = table[24:32] + w * dtable[24:32]
    want_re, want_im = rre.copy(), rim.copy()
    want_re[11:19] += ar * k
    want_im[11:19] += ai * k
    _one_step(table, dtable, 24, w, rre, rim, 11, ar, ai)
    np.testing.assert_allclose(rre, want_re, rtol=0, atol=4e-16 * 8)
    np.testing.assert_allclose(rim, want_im, rtol=0, atol=4e-16 * 8)
    assert np.array_equal(rre[:11], want_re[:11]) and np.array_equal(rre[19:], want_re[19:])


def test_results_outlive_the_next_call_work_buffers_are_internal():
    """The synthesis keeps its large work arrays per thread between calls; what it returns
    must not be one of them: a second call on other scatterers leaves the first result as it
    was."""
    from acoustics.sonar.pulse import Pulse
    from acoustics.synthesis.synthesize import synthesize
    model = _model(13)
    p1, q1 = _scatterers(500, seed=1)
    p2, q2 = _scatterers(700, seed=2)
    kw = dict(pulse=Pulse(), rate_hz=preset.SAMPLE_RATE_HZ, n_samples=1024)
    first = synthesize(model, p1, q1, **kw)
    kept = first.copy()
    second = synthesize(model, p2, q2, **kw)
    assert np.array_equal(first, kept) and not np.array_equal(first, second)
    tk = dict(table=fractional_delay_table(8, 0.4), t0_s=0.0, rate_hz=90910.0, q0=40, n_out=5000)
    trains = spread_arrivals(model, p1, q1, **tk)
    kept = trains.copy()
    spread_arrivals(model, p2, q2, **tk)
    assert np.array_equal(trains, kept)


def test_work_buffers_are_reused_below_their_cap_and_not_kept_above_it():
    from acoustics.synthesis import arrivals as A
    small = A._scratch("test_small", (3, 100), np.float64)
    assert np.shares_memory(small, A._scratch("test_small", (2, 50), np.float64))
    n = A._SCRATCH_MAX_BYTES // 8 + 1
    big = A._scratch("test_big", n, np.float64)
    assert not np.shares_memory(big, A._scratch("test_big", n, np.float64))
    assert getattr(A._WORK, "test_big", None) is None


def test_a_changed_kernel_table_is_never_served_from_the_cache():
    """The table's difference and interleaved forms are kept per read-only table; a writeable
    table (which could change under the same id) is read afresh every call."""
    model = _model(5)
    p, q = _scatterers(200, seed=4)
    kw = dict(t0_s=0.0, rate_hz=90910.0, q0=40, n_out=5000)
    ro = fractional_delay_table(8, 0.4)
    rw = ro.copy()
    a = spread_arrivals(model, p, q, table=ro, **kw)
    assert np.array_equal(spread_arrivals(model, p, q, table=rw, **kw), a)
    rw *= 2.0
    np.testing.assert_allclose(spread_arrivals(model, p, q, table=rw, **kw), 2.0 * a, rtol=1e-12,
                               atol=1e-12 * np.abs(a).max())


def test_a_read_only_view_of_a_changing_table_is_never_served_from_the_cache():
    """Read-only is not unchanging: a read-only view of a writeable array changes with it, so
    the cached forms may only be those of a table that owns its (read-only) memory."""
    model = _model(5)
    p, q = _scatterers(200, seed=4)
    kw = dict(t0_s=0.0, rate_hz=90910.0, q0=40, n_out=5000)
    base = fractional_delay_table(8, 0.4).copy()
    view = base[:]
    view.flags.writeable = False
    a = spread_arrivals(model, p, q, table=view, **kw)
    base *= 2.0
    np.testing.assert_allclose(spread_arrivals(model, p, q, table=view, **kw), 2.0 * a, rtol=1e-12,
                               atol=1e-12 * np.abs(a).max())


def test_the_table_cache_survives_threads_that_evict_at_once():
    """Two Python threads may synthesise at once: the cache's eviction (more tables than it
    keeps) must not raise in one thread because another evicted or added meanwhile."""
    import sys
    import threading
    from acoustics.synthesis import arrivals as A
    tables = []
    for i in range(16):
        t = np.random.default_rng(i).standard_normal((5, 8))
        t.flags.writeable = False
        tables.append(t)
    errors = []

    def work(k):
        try:
            for j in range(3000):
                A._table_forms(tables[(j * 7 + k) % 16])
        except Exception as e:  # any exception is the failure
            errors.append(repr(e))

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads often: the race shows within a few hundred calls
    try:
        for _ in range(6):  # a round shows the race three times in four: six nearly always
            threads = [threading.Thread(target=work, args=(k,)) for k in range(8)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            if errors:
                break
    finally:
        sys.setswitchinterval(interval)
    assert errors == []


def test_no_scatterers_spread_to_silent_trains():
    """An empty scene (S = 0) gives zero trains of the asked length, as synthesize gives silence."""
    model = _model(5)
    kw = dict(table=fractional_delay_table(8, 0.4), t0_s=0.0, rate_hz=90910.0, q0=40, n_out=500)
    out = spread_arrivals(model, np.zeros((0, 3)), np.zeros(0, complex), length=512, **kw)
    assert out.shape == (5, 512) and not out.any()
