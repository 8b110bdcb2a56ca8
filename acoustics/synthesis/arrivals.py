"""The echo model of a point scatterer at every receiver element (thesis eq. 2.16–2.23).

For scatterer P with complex strength q = ρ e^{jφ} and receiver element n::

    r1 = |P − T|,  r2n = |P − R_n|,  τ_n = (r1 + r2n) / c
    A_n = k · S · q · E_t(P) · g(r1) · D_n(P) · g(r2n) · e^{−j2π f0 τ_n}

with T the transmitter's phase centre, E_t its complex directivity (element directivities summed
with their exact path phases relative to T, 1 on axis), S = Σ_e w_e its source level, D_n the
receive element's directivity, g(r) = 10^(−α r/20)/r the one-way spreading and absorption, and k
the ADC scale. The element n then records A_n u(t − τ_n).

Source level: each transmit element driven at unit amplitude radiates pressure 1 at 1 m on its
own axis (the p_0n of thesis eq. 2.9–2.10), so on the array's axis the ganged elements add to
S = Σ w_e — 16 for ABACUS, +24 dB. (Normalising the transmitter to a unit on-axis level instead
would make sixteen elements no louder than one.) Delays are exact per element (no plane-wave approximation) and computed in
float64.

The hot loops are compiled with numba: one pass per scatterer for the transmitter factor, and one
fused pass per (scatterer, element) pair that either returns (τ, A) or spreads A onto the sample
grid through a fractional-delay kernel. Threads split the receiver elements, so every channel is
accumulated in the same order whatever the number of threads (bit-identical results).
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np

from acoustics.sonar.arrays import ElementArray
from acoustics.sonar.directivity import array_response, element_directivity
from acoustics.synthesis.kernels import EXP_SMALL_LIMIT, cis_cycles, exp_small, sine
from acoustics.synthesis.simd import WIDTH, spread8
from acoustics.medium import Medium
from acoustics.sonar import preset

__all__ = ["EchoModel", "transmit_factor", "arrivals", "spread_arrivals"]

_LN10_OVER_20 = np.log(10.0) / 20.0


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _piston(dx, dy, dz, inv_r, kx0, kx1, ky0, ky1, baffle):
    """Far-field rectangular piston directivity towards (dx, dy, dz) at distance 1/inv_r:
    sinc(a) sinc(b), a = (k w / 2) u·x̂, b = (k h / 2) u·ŷ, with (kx0, kx1) = (k w / 2) x̂ and
    (ky0, ky1) = (k h / 2) ŷ (x–y components of the element's local axes, scaled), and one
    division for both factors. :func:`sine` is exact to the last bit for tiny arguments
    (sin a = a there), so sine(a)/a needs no series; but an argument below 1e-150 takes the
    limit 1 (sinc a = 1 − a²/6 rounds to 1 from 1e-8 down): the product a b of one so small
    would underflow (0/0) or keep a subnormal's few bits."""
    if baffle and dz < 0.0:
        return 0.0
    a = (dx * kx0 + dy * kx1) * inv_r
    b = (dx * ky0 + dy * ky1) * inv_r
    za = abs(a) < 1e-150
    zb = abs(b) < 1e-150
    num = (1.0 if za else sine(a)) * (1.0 if zb else sine(b))
    den = (1.0 if za else a) * (1.0 if zb else b)
    return num / den


_BLOCK = 256  # scatterers per vectorised block
_GROUP = 4  # channels whose arrivals one thread interleaves


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _tx_block(qx, qy, qz, rref, cx, cy, cz, ex0, ex1, ey0, ey1, hkw, hkh, w, inv_lam, baffle, acc):
    """Add one transmit element's contribution to a block of scatterers (vectorises).

    ``acc[:n]`` and ``acc[B:B + n]`` hold the real and imaginary running sums."""
    n = qx.shape[0]
    for i in range(n):
        dx = qx[i] - cx
        dy = qy[i] - cy
        dz = qz[i] - cz
        r = max(np.sqrt(dx * dx + dy * dy + dz * dz), 1e-9)
        inv_r = 1.0 / r
        d = _piston(dx, dy, dz, inv_r, hkw * ex0, hkw * ex1, hkh * ey0, hkh * ey1, baffle)
        # R_e − R_T by direct subtraction: at sonar ranges that costs ~1e-14 m, i.e. 1e-11 rad
        sn, cs = cis_cycles(-(r - rref[i]) * inv_lam)
        amp = w * d * rref[i] * inv_r
        acc[i] += amp * cs
        acc[_BLOCK + i] += amp * sn


@nb.njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def _tx_far_field(px, py, pz, c, ex, ey, hkw, hkh, w, ref, inv_lam, baffle, out, r_out):
    """E_t(P) for every scatterer, Σ_e w_e D_e e^{−jk(R_e − R_T)} (R_T/R_e) / Σ w_e, into ``out``,
    and R_T into ``r_out``."""
    n_s = px.shape[0]
    n_e = c.shape[0]
    wsum = 0.0
    for e in range(n_e):
        wsum += w[e]
    n_blocks = (n_s + _BLOCK - 1) // _BLOCK
    for b in nb.prange(n_blocks):
        s0 = b * _BLOCK
        s1 = min(s0 + _BLOCK, n_s)
        qx, qy, qz = px[s0:s1], py[s0:s1], pz[s0:s1]
        rref = np.sqrt((qx - ref[0]) ** 2 + (qy - ref[1]) ** 2 + (qz - ref[2]) ** 2)
        acc = np.zeros(2 * _BLOCK)
        for e in range(n_e):
            _tx_block(qx, qy, qz, rref, c[e, 0], c[e, 1], c[e, 2], ex[e, 0], ex[e, 1], ey[e, 0],
                      ey[e, 1], hkw[e], hkh[e], w[e], inv_lam, baffle, acc)
        for i in range(s1 - s0):
            out[s0 + i] = complex(acc[i], acc[_BLOCK + i]) / wsum
            r_out[s0 + i] = rref[i]
    return out, r_out


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _pair(x, y, z, fre, fim, r1, cx, cy, cz, ex0, ex1, ey0, ey1, hkw, hkh, dre, dim, use_d,
          inv_c, inv_lam, alpha, small_abs, spreading, baffle):
    """(τ, Re A, Im A) of a scatterer at (x, y, z) for the element centred at (cx, cy, cz).

    ``fre + j fim`` already holds k·q·E_t·g(r1)·e^{−α r1}, so the receive leg contributes
    e^{−α (r2 − r1)} (small: the legs differ by at most the array offset) and 1/r2.
    Every argument is a scalar so that the compiled loop keeps them in registers.
    """
    dx = x - cx
    dy = y - cy
    dz = z - cz
    r2 = np.sqrt(dx * dx + dy * dy + dz * dz)
    inv_r = 1.0 / max(r2, 1e-3)  # a scatterer on a face: large but finite
    path = r1 + r2
    g = inv_r if spreading else 1.0
    if alpha != 0.0:
        if small_abs:
            g *= exp_small(-alpha * (r2 - r1))
        else:
            g *= np.exp(-alpha * (r2 - r1))
    sn, cs = cis_cycles(-path * inv_lam)
    if use_d:
        are = dre * g
        aim = dim * g
    else:
        are = _piston(dx, dy, dz, inv_r, hkw * ex0, hkw * ex1, hkh * ey0, hkh * ey1, baffle) * g
        aim = 0.0
    # (fre + j fim)(are + j aim)(cs + j sn)
    pr = fre * are - fim * aim
    pi = fre * aim + fim * are
    return path * inv_c, pr * cs - pi * sn, pr * sn + pi * cs


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _pair_block(qx, qy, qz, qre, qim, q1, cx, cy, cz, ex0, ex1, ey0, ey1, hkw, hkh, inv_c, inv_lam,
                alpha, small_abs, spreading, baffle, buf):
    """:func:`_pair` for a block of scatterers and far-field directivity, vectorised.

    Writes Re A to ``buf[:n]``, Im A to ``buf[B:B + n]`` and τ to ``buf[2B:2B + n]``."""
    n = qx.shape[0]
    kx0, kx1, ky0, ky1 = hkw * ex0, hkw * ex1, hkh * ey0, hkh * ey1
    for i in range(n):
        dx = qx[i] - cx
        dy = qy[i] - cy
        dz = qz[i] - cz
        r2 = np.sqrt(dx * dx + dy * dy + dz * dz)
        inv_r = 1.0 / max(r2, 1e-3)
        path = q1[i] + r2
        g = inv_r if spreading else 1.0
        if small_abs:
            g *= exp_small(-alpha * (r2 - q1[i]))
        else:
            g *= np.exp(-alpha * (r2 - q1[i]))
        g *= _piston(dx, dy, dz, inv_r, kx0, kx1, ky0, ky1, baffle)
        sn, cs = cis_cycles(-path * inv_lam)
        are = g * qre[i]
        aim = g * qim[i]
        buf[i] = are * cs - aim * sn
        buf[_BLOCK + i] = are * sn + aim * cs
        buf[2 * _BLOCK + i] = path * inv_c


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _locate_block(buf, n, t0, fs, q0, n_phase, taps, stride, lo, hi, offset, at):
    """Where each of a block's arrivals lands on the grid, for :func:`spread8` (vectorised).

    Reads τ from ``buf[2B:2B + n]`` (as :func:`_pair_block` leaves it) and overwrites it with
    the weight w of the kernel table's forward difference; writes to ``at[:n]`` the sample of
    the first tap plus ``offset`` (−1: outside [lo, hi), dropped) and to ``at[B:B + n]`` the
    flat index of the table row (rows ``stride`` apart). The same operations as
    :func:`_tap_kernel`, eight arrivals a vector step instead of one at a time in the spreading
    loop."""
    first = offset - taps // 2 + 1
    last_row = float(n_phase - 1)
    for i in range(n):
        # branch-free (selects, bitwise and of the bounds), so that the loop vectorises
        mu = (buf[2 * _BLOCK + i] - t0) * fs + q0
        inside = (mu >= lo) & (mu < hi)
        mu = mu if inside else lo  # an integer conversion of any float is then defined
        m0 = np.floor(mu)  # mu >= lo > 0: the integer part
        x = (mu - m0) * n_phase
        r = min(np.floor(x), last_row)
        buf[2 * _BLOCK + i] = x - r
        at[i] = first + int(m0) if inside else -1
        at[_BLOCK + i] = int(r) * stride


@nb.njit(cache=True, fastmath=True, error_model="numpy", boundscheck=False)
def _spread_block8(at, buf, n, nk, tflat, dflat, rre, rim):
    """Spread a block's located arrivals of ``nk`` channels, taken in turns, one 8-tap vector
    step each (``at`` and ``buf`` as :func:`_locate_block` leaves them, channel j's at offsets
    2jB and 3jB). A function of its own with unsigned offsets: no negative-index wrap-around,
    few live values, so the loop keeps its pointers in registers (13 instructions an
    arrival)."""
    block = np.uint64(_BLOCK)
    for i in range(n):
        ui = np.uint64(i)
        for j in range(nk):
            uj = np.uint64(j)
            base = at[np.uint64(2) * uj * block + ui]
            if base >= 0:
                o = np.uint64(3) * uj * block + ui
                spread8(tflat, dflat, at[(np.uint64(2) * uj + np.uint64(1)) * block + ui],
                        buf[o + np.uint64(2) * block], rre, rim, base, buf[o], buf[o + block])


@nb.njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def _arrivals(px, py, pz, fre, fim, r1, c, ex, ey, hkw, hkh, d_in, use_d, inv_c, inv_lam, alpha,
              small_abs, spreading, baffle):
    n_s, n_r = px.shape[0], c.shape[0]
    tau = np.empty((n_s, n_r))
    amp = np.empty((n_s, n_r), np.complex128)
    for n in nb.prange(n_r):
        cx, cy, cz = c[n, 0], c[n, 1], c[n, 2]
        ex0, ex1, ey0, ey1 = ex[n, 0], ex[n, 1], ey[n, 0], ey[n, 1]
        kw, kh = hkw[n], hkh[n]
        for s in range(n_s):
            d = d_in[s, n] if use_d else 0j
            t, ar, ai = _pair(px[s], py[s], pz[s], fre[s], fim[s], r1[s], cx, cy, cz, ex0, ex1,
                              ey0, ey1, kw, kh, d.real, d.imag, use_d, inv_c, inv_lam, alpha,
                              small_abs, spreading, baffle)
            tau[s, n] = t
            amp[s, n] = complex(ar, ai)
    return tau, amp


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _add_taps(row, ar, ai, tau, t0, fs, q0, table, dtable, lo, hi):
    """Spread one arrival onto a channel's delta train (skipped if outside the record)."""
    mu = (tau - t0) * fs + q0
    if mu < lo or mu >= hi:
        return
    n_phase = dtable.shape[0]
    taps = table.shape[1]
    m0 = int(mu)
    x = (mu - m0) * n_phase
    i = min(int(x), n_phase - 1)
    w = x - i
    base = m0 - taps // 2 + 1
    a = complex(ar, ai)
    # one complex add per tap (re and im in one 16-byte load and store): the same products as
    # two real adds
    for j in range(taps):
        row[base + j] += a * (table[i, j] + w * dtable[i, j])


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _tap_kernel(tau, t0, fs, q0, table, dtable, lo, hi, k):
    """The fractional-delay kernel of one arrival into ``k[:taps]`` (the interpolated table row
    of :func:`_add_taps`) and the sample its first tap lands on; −1 if the arrival is outside
    the record."""
    mu = (tau - t0) * fs + q0
    if mu < lo or mu >= hi:
        return -1
    n_phase = dtable.shape[0]
    taps = table.shape[1]
    m0 = int(mu)
    x = (mu - m0) * n_phase
    i = min(int(x), n_phase - 1)
    w = x - i
    trow = table[i]
    drow = dtable[i]
    for j in range(taps):
        k[j] = trow[j] + w * drow[j]
    return m0 - taps // 2 + 1


@nb.njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _add_split(rre, rim, base, ar, ai, k):
    """Add (ar + j ai) k onto the real and imaginary trains from sample ``base`` on: the
    products of :func:`_add_taps` (one complex times a real tap is two real products), as two
    runs of contiguous real multiply-adds (slices: no index wrap-around per tap), which
    vectorise."""
    taps = k.shape[0]
    sre = rre[base:base + taps]
    sim = rim[base:base + taps]
    for j in range(taps):
        sre[j] += ar * k[j]
        sim[j] += ai * k[j]


@nb.njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def _spread(px, py, pz, fre, fim, r1, c, ex, ey, hkw, hkh, d_in, use_d, inv_c, inv_lam, alpha,
            small_abs, spreading, baffle, table, dtable, tflat, dflat, t0, fs, q0, n_out,
            n_alloc, out):
    """Accumulate every arrival onto its channel's delta train through the kernel table.

    ``table[i, j]`` is the kernel at tap j for fractional offset i / (rows − 1) and ``dtable``
    its forward difference along i; taps land on samples floor(μ) − L/2 + 1 + j with
    μ = (τ − t0) fs + q0, those of arrivals outside [0, n_out) dropped; the trains are
    ``n_alloc`` ≥ n_out long, zero beyond n_out (an FFT length: no padded copy), written to
    ``out`` (n_r, n_alloc), complex, every sample overwritten. One thread per
    channel, scatterers in the given order: the sums do not depend on the number of threads.
    """
    n_s, n_r = px.shape[0], c.shape[0]
    half = table.shape[1] // 2
    lo = float(half)
    hi = float(n_out - half)
    if use_d:  # huygens: directivities given, scalar path
        for n in nb.prange(n_r):
            row = out[n]
            row[:] = 0.0
            for s in range(n_s):
                d = d_in[s, n]
                tau, ar, ai = _pair(px[s], py[s], pz[s], fre[s], fim[s], r1[s], c[n, 0], c[n, 1],
                                    c[n, 2], ex[n, 0], ex[n, 1], ey[n, 0], ey[n, 1], hkw[n],
                                    hkh[n], d.real, d.imag, True, inv_c, inv_lam, alpha,
                                    small_abs, spreading, baffle)
                _add_taps(row, ar, ai, tau, t0, fs, q0, table, dtable, lo, hi)
        return out
    # the far-field loop on its own (a branch between the two inside one parallel loop costs
    # a fifth of the time: the same sums, in the same order); each channel sums its real and
    # imaginary parts in two real trains (contiguous multiply-adds), joined at the end
    taps = table.shape[1]
    n_phase = dtable.shape[0]
    if taps % WIDTH == 0:
        # _GROUP channels a thread, their arrivals taken in turns: an arrival's taps are not
        # loaded straight after the previous arrival of the same channel stored them over the
        # same samples (a store-to-load stall); each channel's sums keep their order
        n_groups = (n_r + _GROUP - 1) // _GROUP
        for g in nb.prange(n_groups):
            n0 = g * _GROUP
            nk = min(_GROUP, n_r - n0)
            buf = np.empty(_GROUP * 3 * _BLOCK)
            at = np.empty(_GROUP * 2 * _BLOCK, np.int64)
            rre = np.zeros(_GROUP * n_alloc)
            rim = np.zeros(_GROUP * n_alloc)
            for s0 in range(0, n_s, _BLOCK):
                s1 = min(s0 + _BLOCK, n_s)
                for j in range(nk):
                    n = n0 + j
                    _pair_block(px[s0:s1], py[s0:s1], pz[s0:s1], fre[s0:s1], fim[s0:s1],
                                r1[s0:s1], c[n, 0], c[n, 1], c[n, 2], ex[n, 0], ex[n, 1],
                                ey[n, 0], ey[n, 1], hkw[n], hkh[n], inv_c, inv_lam, alpha,
                                small_abs, spreading, baffle,
                                buf[j * 3 * _BLOCK:(j + 1) * 3 * _BLOCK])
                    _locate_block(buf[j * 3 * _BLOCK:(j + 1) * 3 * _BLOCK], s1 - s0, t0, fs, q0,
                                  n_phase, taps, 2 * taps, lo, hi, j * n_alloc,
                                  at[j * 2 * _BLOCK:(j + 1) * 2 * _BLOCK])
                if taps == WIDTH:  # the default kernel: one vector step, no loop over taps
                    _spread_block8(at, buf, s1 - s0, nk, tflat, dflat, rre, rim)
                    continue
                for i in range(s1 - s0):
                    for j in range(nk):
                        base = at[j * 2 * _BLOCK + i]
                        if base < 0:
                            continue
                        o = j * 3 * _BLOCK + i
                        row = at[(j * 2 + 1) * _BLOCK + i]
                        w = buf[o + 2 * _BLOCK]
                        for t in range(0, taps, WIDTH):
                            spread8(tflat, dflat, row + t, w, rre, rim, base + t, buf[o],
                                    buf[o + _BLOCK])
            for j in range(nk):
                row = out[n0 + j]
                for m in range(n_alloc):
                    row[m] = complex(rre[j * n_alloc + m], rim[j * n_alloc + m])
        return out
    for n in nb.prange(n_r):
        row = out[n]
        cx, cy, cz = c[n, 0], c[n, 1], c[n, 2]
        ex0, ex1, ey0, ey1 = ex[n, 0], ex[n, 1], ey[n, 0], ey[n, 1]
        kw, kh = hkw[n], hkh[n]
        buf = np.empty(3 * _BLOCK)
        k = np.empty(taps)
        rre = np.zeros(n_alloc)
        rim = np.zeros(n_alloc)
        for s0 in range(0, n_s, _BLOCK):
            s1 = min(s0 + _BLOCK, n_s)
            _pair_block(px[s0:s1], py[s0:s1], pz[s0:s1], fre[s0:s1], fim[s0:s1], r1[s0:s1], cx, cy,
                        cz, ex0, ex1, ey0, ey1, kw, kh, inv_c, inv_lam, alpha, small_abs,
                        spreading, baffle, buf)
            for i in range(s1 - s0):
                base = _tap_kernel(buf[2 * _BLOCK + i], t0, fs, q0, table, dtable, lo, hi, k)
                if base >= 0:
                    _add_split(rre, rim, base, buf[i], buf[_BLOCK + i], k)
        for m in range(n_alloc):
            row[m] = complex(rre[m], rim[m])
    return out


class ReceiverArgs(NamedTuple):
    """The receiver-side arguments of the compiled kernels, in their positional order.

    Attributes
    ----------
    center_m : ndarray, shape (N, 3)
        Receiver element centres (m), sonar frame.
    ex, ey : ndarray, shape (N, 2)
        x–y components of each element's local axes.
    half_kw, half_kh : ndarray, shape (N,)
        k w / 2 and k h / 2 (rad) of each element.
    directivity : ndarray, shape (S, N) complex128, or (1, 1)
        Huygens receive directivities per scatterer and element (only with ``use_directivity``).
    use_directivity : bool
        Take ``directivity`` instead of the far-field sinc pattern.
    inv_c : float
        1 / c (s/m).
    inv_lambda : float
        f0 / c (1/m): the carrier phase in cycles per metre.
    alpha_np_m : float
        Absorption (Np/m; 0 when off).
    cheap_exp : bool
        Whether the receive leg's e^{−α(r2 − r1)} may use the short series (exact to 1e-15).
    spreading, baffle : bool
    """

    center_m: np.ndarray
    ex: np.ndarray
    ey: np.ndarray
    half_kw: np.ndarray
    half_kh: np.ndarray
    directivity: np.ndarray
    use_directivity: bool
    inv_c: float
    inv_lambda: float
    alpha_np_m: float
    cheap_exp: bool
    spreading: bool
    baffle: bool


@dataclass(frozen=True, eq=False)
class EchoModel:
    """Everything about the sonar and water that a ping's echoes need, fixed for a run.

    Attributes
    ----------
    transmitter, receiver : ElementArray
        The ganged transmitter and the recorded receiver channels (sonar frame).
    medium : Medium
    center_frequency_hz : float
    scale_counts : float
        k: ADC counts per unit pressure (a unit-driven element gives 1 at 1 m on its axis).
    fidelity : {"far_field", "huygens"}
    subdivisions : (int, int)
    baffle, spreading, absorption : bool
    """

    transmitter: ElementArray
    receiver: ElementArray
    medium: Medium
    center_frequency_hz: float = preset.CENTER_FREQUENCY_HZ
    scale_counts: float = 1.0
    fidelity: str = "far_field"
    subdivisions: tuple = (4, 4)
    baffle: bool = True
    spreading: bool = True
    absorption: bool = True

    @property
    def wavenumber_rad_m(self) -> float:
        return self.medium.wavenumber_rad_m(self.center_frequency_hz)

    @property
    def source_level(self) -> float:
        """S = Σ w_e: on-axis pressure at 1 m of the ganged transmitter (unit drive per element)."""
        return float(self.transmitter.weight.sum())

    def receiver_args(self, p) -> "ReceiverArgs":
        """Receiver-side arguments of the compiled kernels for scatterers ``p`` (S, 3)."""
        rx = self.receiver
        ex, ey = rx.local_axes
        k = self.wavenumber_rad_m
        if self.fidelity == "huygens":
            d_in = element_directivity(rx, p, wavenumber_rad_m=k, fidelity="huygens",
                                       subdivisions=self.subdivisions, baffle=self.baffle)
        else:
            d_in = np.zeros((1, 1), np.complex128)
        alpha = _alpha_np_per_m(self)
        # |r2 − r1| <= |R_n − T|, so this bound decides if the cheap exponential is exact
        reach = float(np.max(np.linalg.norm(rx.center_m - self.transmitter.phase_center_m, axis=1)))
        return ReceiverArgs(
            center_m=np.ascontiguousarray(rx.center_m), ex=np.ascontiguousarray(ex[:, :2]),
            ey=np.ascontiguousarray(ey[:, :2]), half_kw=0.5 * k * rx.width_m,
            half_kh=0.5 * k * rx.height_m, directivity=np.ascontiguousarray(d_in, np.complex128),
            use_directivity=self.fidelity == "huygens", inv_c=1.0 / self.medium.sound_speed_m_s,
            inv_lambda=self.center_frequency_hz / self.medium.sound_speed_m_s, alpha_np_m=alpha,
            cheap_exp=alpha * reach <= EXP_SMALL_LIMIT, spreading=self.spreading,
            baffle=self.baffle)


_WORK = threading.local()
#: the largest work buffer kept between calls (bytes); a larger one is allocated afresh each time,
#: so that what a thread keeps stays below 6 x this (the synthesis' six buffers) whatever the
#: scene: 10⁵ scatterers x 32 channels need 4.9 MB at most
_SCRATCH_MAX_BYTES = 8_000_000


def _scratch(name: str, shape, dtype) -> np.ndarray:
    """This thread's work buffer ``name`` as an uninitialised array of ``shape``, reused from
    call to call (kept at the largest size asked for, up to ``_SCRATCH_MAX_BYTES``). A fresh
    multi-megabyte array is mapped anew by the allocator and pays a page fault per 4 KiB on its
    first touch — about 0.2 ms per MB on the machine of docs/performance.md, 2.5 ms of a
    10⁵ x 32 synthesis. The caller must be done with the previous contents: only the
    synthesis' internal inputs and trains use it."""
    size = math.prod(shape) if isinstance(shape, tuple) else int(shape)
    if size * np.dtype(dtype).itemsize > _SCRATCH_MAX_BYTES:
        return np.empty(shape, dtype)
    buf = getattr(_WORK, name, None)
    if buf is None or buf.dtype != dtype or buf.size < size:
        buf = np.empty(size, dtype)
        setattr(_WORK, name, buf)
    return buf[:size].reshape(shape)


def _positions(positions) -> np.ndarray:
    p = np.ascontiguousarray(np.asarray(positions, float).reshape(-1, 3))
    if not np.all(np.isfinite(p)):
        raise ValueError("scatterer positions must be finite")
    return p


def _transmit(model: EchoModel, p: np.ndarray, scratch: bool = False):
    """E_t(P) (complex, shape (S,)) and r1 = |P − T| (m, shape (S,)); ``scratch``: far-field
    results in this thread's work buffers (see :func:`_scratch`), for a caller that drops them
    before the next call."""
    tx = model.transmitter
    ref = tx.phase_center_m
    k = model.wavenumber_rad_m
    if model.fidelity == "huygens":
        e_t = array_response(tx, p, wavenumber_rad_m=k, fidelity="huygens",
                             subdivisions=model.subdivisions, baffle=model.baffle, reference_m=ref)
        return e_t, np.linalg.norm(p - ref, axis=1)
    ex, ey = tx.local_axes
    if scratch:
        e_t, r1 = _scratch("e_t", p.shape[0], np.complex128), _scratch("r1", p.shape[0], np.float64)
    else:
        e_t, r1 = np.empty(p.shape[0], np.complex128), np.empty(p.shape[0])
    _tx_far_field(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
                  np.ascontiguousarray(p[:, 2]), np.ascontiguousarray(tx.center_m),
                  np.ascontiguousarray(ex[:, :2]), np.ascontiguousarray(ey[:, :2]),
                  0.5 * k * tx.width_m, 0.5 * k * tx.height_m, tx.weight, ref,
                  model.center_frequency_hz / model.medium.sound_speed_m_s, model.baffle, e_t, r1)
    return e_t, r1


def _alpha_np_per_m(model: EchoModel) -> float:
    a = model.medium.absorption_db_per_m
    return a * _LN10_OVER_20 if model.absorption and a > 0 else 0.0


def transmit_factor(model: EchoModel, positions_m, strength):
    """Per-scatterer factor k·S·q·E_t(P)·g(r1) and the transmit leg r1.

    Parameters
    ----------
    model : EchoModel
    positions_m : array_like, shape (S, 3)
        Scatterers (m), sonar frame.
    strength : array_like, shape (S,)
        Complex backscatter amplitude q = ρ e^{jφ} (m).

    Returns
    -------
    factor : ndarray, shape (S,), complex128
        In ADC counts x m (the receive leg g(r2) supplies the remaining 1/m).
    r1_m : ndarray, shape (S,)
        Distance (m) from the transmitter's phase centre.
    """
    p = _positions(positions_m)
    e_t, r1 = _transmit(model, p)
    g1 = model.medium.one_way_gain(r1, spreading=model.spreading, absorption=model.absorption)
    return (model.scale_counts * model.source_level * np.asarray(strength, complex).reshape(-1)
            * e_t * g1, r1)


def _kernel_inputs(model, positions_m, strength, *, by_range=False, receive_positions_m=None):
    """Columns the compiled kernels take, optionally reordered by range (see spread_arrivals).

    ``receive_positions_m`` (S, 3), when given, is where the receive leg starts: the image point of
    a path that bounces on its way back (multipath); the transmit leg uses ``positions_m``.
    The six columns are this thread's work buffers (:func:`_scratch`): the next call overwrites
    them, so a caller uses them before it calls again (or copies them)."""
    p = _positions(positions_m)
    q = np.asarray(strength, complex).reshape(-1)
    if q.shape[0] != p.shape[0]:
        raise ValueError("positions_m and strength must describe the same scatterers")
    e_t, r1 = _transmit(model, p, scratch=True)
    alpha = _alpha_np_per_m(model)
    prx = p if receive_positions_m is None else _positions(receive_positions_m)
    if prx.shape != p.shape:
        raise ValueError("receive_positions_m must have the shape of positions_m")
    rx = model.receiver_args(prx)
    if receive_positions_m is not None and alpha and rx.cheap_exp:
        # |r2 − r1| <= ||P_rx − T| − r1| + |R_n − T|: is the cheap e^{−α(r2 − r1)} still exact?
        reach = float(np.max(np.linalg.norm(model.receiver.center_m - model.transmitter.phase_center_m, axis=1)))
        gap = float(np.max(np.abs(np.linalg.norm(prx - model.transmitter.phase_center_m, axis=1) - r1)))
        if alpha * (gap + reach) > EXP_SMALL_LIMIT:
            rx = rx._replace(cheap_exp=False)
    if by_range:
        # a 16-bit key gets numpy's linear-time radix sort; ties keep the input order
        key = (r1 * (32767.0 / max(float(r1.max(initial=0.0)), 1e-12))).astype(np.int16)
        order = np.argsort(key, kind="stable")
        if rx.use_directivity:  # huygens directivities follow their scatterers
            rx = rx._replace(directivity=rx.directivity[order])
    else:
        order = np.arange(r1.size)
    # e^{−2α r1} by numpy's vectorised exp (numba's calls libm once per scatterer)
    decay = _scratch("decay", r1.size, np.float64)
    if alpha:
        np.exp(np.multiply(r1, -2.0 * alpha, out=decay), out=decay)
    else:
        decay.fill(1.0)
    f_s = _scratch("factor", r1.size, np.complex128)
    _factor(model.scale_counts * model.source_level, q, e_t, decay, r1, model.spreading, f_s)
    cols = _scratch("columns", (6, r1.size), np.float64)
    _columns(order, prx, f_s, r1, cols)
    return tuple(cols) + tuple(rx)


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _factor(scale, q, e_t, decay, r1, spreading, out):
    """The scatterer factor k S q E_t g(r1) with, folded in here, the receive leg's absorption
    up to e^{−α(r2 − r1)}: ``scale`` q E_t e^{−2α r1} / r1 (``decay`` = e^{−2α r1}; 1/r1 only
    with ``spreading``), multiplied in that order, into ``out`` (S,), in input order (one
    sequential pass: the gather that reorders it then reads one array, not four)."""
    for s in nb.prange(q.shape[0]):
        w = decay[s]
        if spreading:
            w = w / max(r1[s], 1e-3)
        out[s] = scale * q[s] * e_t[s] * w


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _columns(order, prx, f_s, r1, out):
    """The kernels' six input columns (x, y, z of the receive leg's start, Re and Im of the
    scatterer factor, r1), contiguous, scatterer ``order[i]`` in row i, into ``out`` (6, S):
    one parallel pass instead of six strided takes (copies: the values are unchanged)."""
    n = order.shape[0]
    for i in nb.prange(n):
        s = order[i]
        out[0, i] = prx[s, 0]
        out[1, i] = prx[s, 1]
        out[2, i] = prx[s, 2]
        out[3, i] = f_s[s].real
        out[4, i] = f_s[s].imag
        out[5, i] = r1[s]


def arrivals(model: EchoModel, positions_m, strength, *, receive_positions_m=None):
    """Delay and complex amplitude of every (scatterer, receiver element) arrival.

    ``receive_positions_m`` (S, 3): where each receive leg starts, when it differs from the
    transmit leg's end (a bounce on the way back: the image point).

    Returns
    -------
    tau_s : ndarray, shape (S, N_rx), float64
        Two-way delays (s) from the transmitter's phase centre to each element.
    amplitude : ndarray, shape (S, N_rx), complex128
        A_n in ADC counts, carrier phase e^{−j2πf0τ} included.
    """
    return _arrivals(*_kernel_inputs(model, positions_m, strength,
                                     receive_positions_m=receive_positions_m))


def spread_arrivals(model: EchoModel, positions_m, strength, *, table, t0_s, rate_hz, q0, n_out,
                    receive_positions_m=None, length=None, scratch=False):
    """The channels' fractional-delay delta trains, shape (N_rx, length), complex128.

    Arrivals land on samples [0, n_out) (the rest are dropped); ``length`` (≥ n_out, default
    n_out) pads the trains with zeros, e.g. to the FFT length that convolves them. Scatterers are
    visited in order of range (a stable sort), so the delta trains are written nearly
    sequentially; the order is fixed by the scene, never by the thread count. ``scratch``: the
    trains in this thread's work buffer (see :func:`_scratch`), overwritten by the next call
    that asks for it — for a caller that is done with them by then.
    """
    args = _kernel_inputs(model, positions_m, strength, by_range=True,
                          receive_positions_m=receive_positions_m)
    table = np.ascontiguousarray(table)
    length = int(n_out) if length is None else int(length)
    if length < n_out:
        raise ValueError(f"length {length} < n_out {n_out}")
    dtable, tflat, dflat = _table_forms(table)
    n_rx = model.receiver.n_elements
    out = (_scratch("trains", (n_rx, length), np.complex128) if scratch
           else np.empty((n_rx, length), np.complex128))
    _spread(*args, table, dtable, tflat, dflat, float(t0_s), float(rate_hz), float(q0),
            int(n_out), length, out)
    return out


_TABLE_FORMS: dict = {}
_TABLE_FORMS_LOCK = threading.Lock()


def _table_forms(table):
    """(forward difference, interleaved views) of a kernel table, made once per table object
    (:func:`~acoustics.synthesis.synthesize.fractional_delay_table` returns the same read-only
    table for the same arguments): a few recent tables are kept, each with its forms."""
    # only a read-only table that owns its memory cannot change under its id (a read-only view
    # of a writeable array changes with it)
    fixed = not table.flags.writeable and table.flags.owndata
    hit = _TABLE_FORMS.get(id(table))
    if fixed and hit is not None and hit[0] is table:
        return hit[1:]
    dtable = np.ascontiguousarray(np.diff(table, axis=0))
    forms = (dtable,) + _interleaved(table, dtable)
    if fixed:
        # threads synthesising at once: one evicting while another evicts or adds would raise
        # (KeyError, or "dictionary changed size during iteration"); lookups need no lock
        with _TABLE_FORMS_LOCK:
            if len(_TABLE_FORMS) >= 8:
                _TABLE_FORMS.pop(next(iter(_TABLE_FORMS)))
            _TABLE_FORMS[id(table)] = (table,) + forms
    return forms


def _interleaved(table, dtable):
    """Row i of the kernel table and of its forward difference side by side in one buffer
    aligned to 64 bytes (the vector steps' table loads then touch two whole cache lines per
    arrival instead of parts of four), as two flat views: ``tflat[i * 2L:]`` starts row i of
    ``table``, ``dflat[i * 2L:]`` row i of ``dtable`` (the same numbers, copied)."""
    rows, taps = dtable.shape
    raw = np.empty(rows * 2 * taps + 8)
    skip = (-raw.ctypes.data % 64) // 8
    both = raw[skip:skip + rows * 2 * taps].reshape(rows, 2 * taps)
    both[:, :taps] = table[:rows]
    both[:, taps:] = dtable
    flat = both.ravel()
    return flat, flat[taps:]


# The compiled steps, for the other synthesis kernels (acoustics/synthesis/doppler_bank.py):
# one scatterer-element pair, a block of them, the spread of an arrival onto a channel's grid,
# the kernels' input columns, and the block size.
pair = _pair
pair_block = _pair_block
add_taps = _add_taps
tap_kernel = _tap_kernel
add_split = _add_split
kernel_inputs = _kernel_inputs
BLOCK = _BLOCK
