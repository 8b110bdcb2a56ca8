"""Doppler-shifted echoes in the fast synthesis: a small bank of replicas, one pass over the pairs.

An echo shifted by f (Hz) is A u(s) e^{j2πfs}, s = t − τ. For an LFM pulse u(s) = a(s/T)
e^{jπK(s − T/2)²} the shift is, to within the envelope, a delay — the range–Doppler coupling:
completing the square,

    u(s) e^{j2πfs} = e^{jπfT} e^{−jπf²g} r_f(s + fg),   g = 1/K,
    r_f(t) = a((t − fg)/T) e^{jπK(t − T/2)²},

so the echo is r_f delayed by τ − fg with a phase. r_f is the *unshifted* chirp under an envelope
that slides by fg (0.26 ms for 750 Hz at K = 20 kHz / 7 ms), smooth in f: it is interpolated in f
by Lagrange polynomials through G Chebyshev nodes F_j spanning the ping's shifts,
r_f ≈ Σ_j L_j(f) r_{F_j}. Each scatterer then costs *one* evaluation of its geometry per element
(as an unshifted echo) and G weighted spreads onto G delta trains; each train is convolved with
its replica r_{F_j} by one FFT. A CW pulse (B = 0) has no coupling (g = 0): the same bank then
interpolates e^{j2πf(s − T/2)} itself, which needs more nodes.

G is the smallest number of nodes whose worst error over the ping's range of shifts,
max_f ‖exact − bank‖₂ / ‖u‖₂ on the fine grid, is below ``error_db``: measured here, not
bounded, for the pulse and range at hand (:func:`bank_error_db`); docs/accuracy.md ("Doppler
bank") tabulates it against the exact synthesis. For the ABACUS pulse, shifts spread over
±750 Hz need 3 nodes for −46 dB, 6 for −55 dB.

Threads split the receiver channels, as in the unshifted kernel: the sums do not depend on
the number of threads.
"""
from __future__ import annotations

from functools import lru_cache

import numba as nb
import numpy as np
import scipy.fft as sfft

from acoustics.sonar.pulse import TAPERS
from acoustics.synthesis.arrivals import BLOCK as _BLOCK
from acoustics.synthesis.arrivals import add_split as _add_split
from acoustics.synthesis.arrivals import add_taps as _add_taps
from acoustics.synthesis.arrivals import kernel_inputs as _kernel_inputs
from acoustics.synthesis.arrivals import pair as _pair
from acoustics.synthesis.arrivals import pair_block as _pair_block
from acoustics.synthesis.arrivals import tap_kernel as _tap_kernel
from acoustics.synthesis.simd import WIDTH, spread8

__all__ = ["bank_nodes", "bank_error_db", "bank_weights", "bank_replicas", "spread_bank",
           "MAX_NODES"]

#: most replicas a bank uses (beyond this the error target is not reached: the nodes stay here)
MAX_NODES = 24


def _chebyshev(lo: float, hi: float, n: int) -> np.ndarray:
    k = np.arange(n)
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.cos((2 * k + 1) * np.pi / (2 * n))


def bank_weights(f_hz, nodes_hz):
    """Lagrange weights L_j(f) of each shift on the nodes, shape (S, G); exactly 1 on a node."""
    f = np.asarray(f_hz, float).reshape(-1, 1)
    nodes = np.asarray(nodes_hz, float)
    w = np.ones((f.shape[0], nodes.size))
    for j in range(nodes.size):
        for m in range(nodes.size):
            if m != j:
                w[:, j] *= (f[:, 0] - nodes[m]) / (nodes[j] - nodes[m])
    return w


def _coupling(pulse) -> float:
    """g = 1/K (s/Hz), 0 for a CW pulse."""
    k = pulse.chirp_rate_hz_s
    return 0.0 if k == 0 else 1.0 / k


def _shifted(pulse, t_s, f_hz):
    """r_f(t) on times t (s), shape (len(f), len(t)): e^{jπf²g} u(t − fg) e^{j2πf(t − fg − T/2)}."""
    g = _coupling(pulse)
    f = np.asarray(f_hz, float).reshape(-1, 1)
    s = np.asarray(t_s, float)[None, :] - f * g
    return (pulse.envelope(s) * np.exp(2j * np.pi * f * (s - 0.5 * pulse.duration_s))
            * np.exp(1j * np.pi * f * f * g))


def bank_replicas(pulse, rate_hz: float, nodes_hz):
    """The replicas r_{F_j} sampled at t = m/fs − pre_s, shape (G, M), and pre_s (s).

    ``pre_s`` ≥ 0 is how far the earliest replica starts before the pulse's own start."""
    nodes = np.asarray(nodes_hz, float)
    g = _coupling(pulse)
    lo = min(0.0, float(np.min(nodes * g)))
    hi = pulse.duration_s + max(0.0, float(np.max(nodes * g)))
    pre = np.ceil(-lo * rate_hz - 1e-9) / rate_hz
    m = int(np.floor((hi + pre) * rate_hz + 1e-9)) + 1
    t = np.arange(m) / rate_hz - pre
    return _shifted(pulse, t, nodes), float(pre)


@lru_cache(maxsize=256)
def _error_db_cached(pulse, rate_hz: float, lo: float, hi: float, n: int) -> float:
    fs = rate_hz
    t = np.arange(-int(np.ceil(0.1 * pulse.duration_s * fs)),
                  int(np.ceil(1.1 * pulse.duration_s * fs))) / fs
    f = np.linspace(lo, hi, 41)
    nodes = _chebyshev(lo, hi, n)
    g = _coupling(pulse)
    w = bank_weights(f, nodes)
    if g != 0.0:
        # a linear chirp u(s) = a(s) e^{jπK(s − T/2)²} (g = 1/K): r_F(s) = a(s − Fg) e^{jπK(s − T/2)²}
        # and both the exact echo and the bank's carry the same phase e^{jπK(s + fg − T/2)² −
        # jπf²g}, so the error is ‖a(s) − Σ L_j a(s + (f − F_j)g)‖ (real tapers, no exponentials)
        def taper(x):
            inside = (x >= 0.0) & (x <= pulse.duration_s)
            return np.where(inside, TAPERS[pulse.taper](np.where(inside, x, 0.0) / pulse.duration_s), 0.0)

        a0 = taper(t)
        approx = np.zeros((f.size, t.size))
        for j, fj in enumerate(nodes):
            approx += w[:, j:j + 1] * taper(t[None, :] + (f[:, None] - fj) * g)
        err = np.linalg.norm(a0[None, :] - approx, axis=1).max() / max(np.linalg.norm(a0), 1e-300)
        return float(20 * np.log10(max(err, 1e-300)))
    # exact: u(s) e^{j2πf(s − T/2)}; bank: e^{−jπf²g} Σ L_j r_{F_j}(s + fg)
    exact = pulse.envelope(t)[None, :] * np.exp(2j * np.pi * f[:, None] * (t[None, :] - 0.5 * pulse.duration_s))
    approx = np.zeros_like(exact)
    for j, fj in enumerate(nodes):
        approx += w[:, j:j + 1] * _shifted_at(pulse, t[None, :] + f[:, None] * g, fj)
    approx *= np.exp(-1j * np.pi * f * f * g)[:, None]
    err = np.linalg.norm(exact - approx, axis=1).max() / max(np.linalg.norm(pulse.envelope(t)), 1e-300)
    return float(20 * np.log10(max(err, 1e-300)))


def _shifted_at(pulse, t2d, fj):
    g = _coupling(pulse)
    s = t2d - fj * g
    return pulse.envelope(s) * np.exp(2j * np.pi * fj * (s - 0.5 * pulse.duration_s)) * np.exp(1j * np.pi * fj * fj * g)


def bank_error_db(pulse, rate_hz: float, lo_hz: float, hi_hz: float, n_nodes: int) -> float:
    """Worst error (dB re the pulse) of an ``n_nodes`` bank over shifts in [lo_hz, hi_hz]:
    max_f ‖u(s)e^{j2πfs} − bank‖₂ / ‖u‖₂ on a grid of 41 shifts, sampled at ``rate_hz``."""
    if hi_hz - lo_hz <= 0:
        return -300.0
    # the error depends on the shifts' offsets from the nodes alone (the bank and the exact echo
    # share each shift's phase): keyed by the span, consecutive pings share their tables
    return _error_db_cached(pulse, float(rate_hz), 0.0, float(hi_hz) - float(lo_hz), int(n_nodes))


def bank_nodes(pulse, rate_hz: float, f_hz, error_db: float) -> np.ndarray:
    """The fewest Chebyshev nodes over the shifts' range whose bank meets ``error_db``
    (at most :data:`MAX_NODES`); one node (exact) when every shift is the same."""
    f = np.asarray(f_hz, float)
    lo, hi = float(f.min()), float(f.max())
    if hi - lo <= 1e-9 * max(1.0, abs(hi)):
        return np.array([0.5 * (lo + hi)])
    # the range rounded out to 1 Hz: the error table is cached across pings
    lo, hi = np.floor(lo), np.ceil(hi)
    for n in range(2, MAX_NODES + 1):
        if bank_error_db(pulse, rate_hz, lo, hi, n) <= error_db:
            return _chebyshev(lo, hi, n)
    return _chebyshev(lo, hi, MAX_NODES)


@nb.njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def _spread_bank(px, py, pz, fre, fim, r1, c, ex, ey, hkw, hkh, d_in, use_d, inv_c, inv_lam, alpha,
                 small_abs, spreading, baffle, shift, wre, wim, table, dtable, t0, fs, q0, n_out,
                 n_alloc):
    """:func:`acoustics.synthesis.arrivals._spread` with G weighted trains per channel.

    Each arrival's delay is reduced by ``shift[s]`` (s) and its amplitude, times
    ``wre[s, j] + j wim[s, j]``, spread onto train j. One thread per channel."""
    n_s, n_r = px.shape[0], c.shape[0]
    n_g = wre.shape[1]
    half = table.shape[1] // 2
    out = np.zeros((n_g, n_r, n_alloc), np.complex128)
    lo = float(half)
    hi = float(n_out - half)
    if use_d:  # huygens: directivities given, scalar path
        for n in nb.prange(n_r):
            for s in range(n_s):
                d = d_in[s, n]
                tau, ar, ai = _pair(px[s], py[s], pz[s], fre[s], fim[s], r1[s], c[n, 0], c[n, 1],
                                    c[n, 2], ex[n, 0], ex[n, 1], ey[n, 0], ey[n, 1], hkw[n],
                                    hkh[n], d.real, d.imag, True, inv_c, inv_lam, alpha,
                                    small_abs, spreading, baffle)
                tau -= shift[s]
                for j in range(n_g):
                    _add_taps(out[j, n], ar * wre[s, j] - ai * wim[s, j],
                              ar * wim[s, j] + ai * wre[s, j], tau, t0, fs, q0, table, dtable,
                              lo, hi)
        return out
    # the far-field loop on its own: a branch inside the parallel loop slows it (as _spread);
    # an arrival's kernel found once for its G trains, each summed as two real trains
    taps = table.shape[1]
    n_phase = dtable.shape[0]
    vec = taps % WIDTH == 0
    tflat = table.ravel()
    dflat = dtable.ravel()
    for n in nb.prange(n_r):
        cx, cy, cz = c[n, 0], c[n, 1], c[n, 2]
        ex0, ex1, ey0, ey1 = ex[n, 0], ex[n, 1], ey[n, 0], ey[n, 1]
        kw, kh = hkw[n], hkh[n]
        buf = np.empty(3 * _BLOCK)
        k = np.empty(taps)
        rre = np.zeros((n_g, n_alloc))
        rim = np.zeros((n_g, n_alloc))
        for s0 in range(0, n_s, _BLOCK):
            s1 = min(s0 + _BLOCK, n_s)
            _pair_block(px[s0:s1], py[s0:s1], pz[s0:s1], fre[s0:s1], fim[s0:s1], r1[s0:s1],
                        cx, cy, cz, ex0, ex1, ey0, ey1, kw, kh, inv_c, inv_lam, alpha,
                        small_abs, spreading, baffle, buf)
            for i in range(s1 - s0):
                s = s0 + i
                ar, ai = buf[i], buf[_BLOCK + i]
                if vec:
                    # eight taps a vector step (acoustics/synthesis/simd.py): the kernel is
                    # formed again per train, the same fused multiply-adds, the same sums
                    mu = (buf[2 * _BLOCK + i] - shift[s] - t0) * fs + q0
                    if mu < lo or mu >= hi:
                        continue
                    m0 = int(mu)
                    x = (mu - m0) * n_phase
                    r = min(int(x), n_phase - 1)
                    w = x - r
                    base = m0 - half + 1
                    for j in range(n_g):
                        br = ar * wre[s, j] - ai * wim[s, j]
                        bi = ar * wim[s, j] + ai * wre[s, j]
                        for t in range(0, taps, WIDTH):
                            spread8(tflat, dflat, r * taps + t, w, rre[j], rim[j], base + t,
                                    br, bi)
                    continue
                base = _tap_kernel(buf[2 * _BLOCK + i] - shift[s], t0, fs, q0, table, dtable,
                                   lo, hi, k)
                if base < 0:
                    continue
                for j in range(n_g):
                    _add_split(rre[j], rim[j], base, ar * wre[s, j] - ai * wim[s, j],
                               ar * wim[s, j] + ai * wre[s, j], k)
        for j in range(n_g):
            for m in range(n_alloc):
                out[j, n, m] = complex(rre[j, m], rim[j, m])
    return out


def spread_bank(model, positions_m, strength, weights, shift_s, *, table, t0_s, rate_hz, q0,
                n_out, receive_positions_m=None, length=None):
    """The G banks' delta trains of every channel, shape (G, N_rx, length), complex128.

    Parameters
    ----------
    model : EchoModel
    positions_m : ndarray, shape (S, 3)
    strength : ndarray, shape (S,), complex
    weights : ndarray, shape (S, G), complex
        Each scatterer's weight on each replica.
    shift_s : ndarray, shape (S,)
        How much earlier (s) each arrival is spread than its delay.
    table, t0_s, rate_hz, q0, n_out, receive_positions_m, length
        As :func:`acoustics.synthesis.arrivals.spread_arrivals`.
    """
    p = np.asarray(positions_m, float).reshape(-1, 3)
    q = np.asarray(strength, complex).reshape(-1)
    prx = None if receive_positions_m is None else np.asarray(receive_positions_m, float).reshape(-1, 3)
    # in order of range, as the unshifted kernel: the trains are written nearly sequentially;
    # the order comes from the scene, never from the thread count
    r1 = np.linalg.norm(p - model.transmitter.phase_center_m, axis=1)
    key = (r1 * (32767.0 / max(float(r1.max()), 1e-12))).astype(np.int16)
    order = np.argsort(key, kind="stable")
    p, q, w, sh = p[order], q[order], np.asarray(weights)[order], np.asarray(shift_s, float)[order]
    prx = None if prx is None else prx[order]
    args = _kernel_inputs(model, p, q, by_range=False, receive_positions_m=prx)
    length = int(n_out) if length is None else int(length)
    out = _spread_bank(*args, np.ascontiguousarray(sh), np.ascontiguousarray(w.real),
                       np.ascontiguousarray(w.imag), np.ascontiguousarray(table),
                       np.ascontiguousarray(np.diff(table, axis=0)), float(t0_s), float(rate_hz),
                       float(q0), int(n_out), length)
    return out


def synthesize_bank(model, p, q, fd, pulse, fs, n, t0, taps, up, prx, error_db, table_fn,
                    fast_len, every_up_th):
    """Complex baseband samples (N_rx, n) of every scatterer, the shifted ones (fd ≠ 0)
    through the bank, the others through the plain replica, all under one inverse FFT.

    The bank's trains cover only the stretch of the record its echoes can reach (the two legs'
    lengths from the sonar's origin, ± the arrays' reach, the shifts and the kernel) when that
    is less than half the record: a school's echoes need not pay for the whole record's FFTs.
    """
    fine = fs * up
    moving = np.flatnonzero(fd != 0)
    still = np.flatnonzero(fd == 0)
    fm = fd[moving]
    nodes = bank_nodes(pulse, fine, fm, error_db)
    reps, pre = bank_replicas(pulse, fine, nodes)
    m = reps.shape[1]
    g = _coupling(pulse)
    shift = fm * g + pre
    # room for an echo that starts up to a replica plus its shift before sample 0
    lead = m + taps + int(np.ceil((pre + float(np.max(np.abs(fm))) * abs(g)) * fine)) + 1
    q0 = up * -(-lead // up)
    n_out = q0 + up * n + taps
    widest = float(np.max(np.abs(nodes)))
    band = min(pulse.bandwidth_hz + 4.0 / pulse.duration_s + 2.0 * widest, 0.98 * fine)
    table = table_fn(int(taps), (fine - band) / fine)
    nfft = fast_len(n_out + m - 1, up)
    n_rx = model.receiver.n_elements
    spec = None
    if still.size:
        from acoustics.synthesis.arrivals import spread_arrivals
        # the plain replica on the bank's time axis (it starts ``pre`` after the bank's)
        rep0 = pulse.envelope(np.arange(m) / fine - pre)
        delta = spread_arrivals(model, p[still], q[still], table=table, t0_s=t0 + pre,
                                rate_hz=fine, q0=q0, n_out=n_out,
                                receive_positions_m=None if prx is None else prx[still],
                                length=nfft)
        spec = sfft.fft(delta, axis=1, workers=-1, overwrite_x=True)
        spec *= sfft.fft(rep0, nfft)
    T = pulse.duration_s
    w = bank_weights(fm, nodes) * (np.exp(1j * np.pi * fm * T) * np.exp(-1j * np.pi * fm * fm * g))[:, None]
    pm, qm = p[moving], q[moving]
    rm = None if prx is None else prx[moving]
    # the stretch of the fine grid the shifted echoes can touch
    c = model.medium.sound_speed_m_s
    reach = max(float(np.max(np.linalg.norm(model.receiver.center_m, axis=1))),
                float(np.linalg.norm(model.transmitter.phase_center_m)))
    path = np.linalg.norm(pm, axis=1) + np.linalg.norm(pm if rm is None else rm, axis=1)
    g_lo = max(0, int(np.floor(((path.min() - 2 * reach) / c - shift.max() - t0) * fine + q0)) - taps - 2)
    g_hi = min(n_out, int(np.ceil(((path.max() + 2 * reach) / c - shift.min() - t0) * fine + q0)) + taps + 2)
    span = g_hi - g_lo
    late = None
    if span > 0:
        short = 2 * (span + m) < nfft
        nf = sfft.next_fast_len(span + m - 1) if short else nfft
        trains = spread_bank(model, pm, qm, w, shift, table=table,
                             t0_s=t0 + (g_lo - q0) / fine if short else t0, rate_hz=fine,
                             q0=0 if short else q0, n_out=span if short else n_out,
                             receive_positions_m=rm, length=nf)
        part = None
        for j in range(nodes.size):
            f_j = sfft.fft(trains[j], axis=1, workers=-1, overwrite_x=True)
            f_j *= sfft.fft(reps[j], nf)
            if part is None:
                part = f_j
            else:
                part += f_j
        if not short:
            spec = part if spec is None else spec + part
        else:
            y = sfft.ifft(part, axis=1, workers=-1, overwrite_x=True)[:, :span + m - 1]
            acc = np.zeros((n_rx, nfft), complex)
            acc[:, g_lo:g_lo + span + m - 1] = y
            late = acc[:, q0:q0 + up * n:up]
    out = every_up_th(spec, up, q0, n) if spec is not None else None
    if late is not None:
        out = late if out is None else out + late
    if out is None:
        return np.zeros((n_rx, n), complex)
    return out
