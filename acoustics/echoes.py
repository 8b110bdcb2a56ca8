"""The echo model of a point scatterer at every receiver element (thesis eq. 2.16–2.23).

For scatterer P with complex strength q = ρ e^{jφ} and receiver element n::

    r1 = |P − T|,  r2n = |P − R_n|,  τ_n = (r1 + r2n) / c
    A_n = k · q · E_t(P) · g(r1) · D_n(P) · g(r2n) · e^{−j2π f0 τ_n}

with T the transmitter's phase centre, E_t its complex response (element directivities summed
with their exact path phases relative to T), D_n the receive element's directivity, g(r) =
10^(−α r/20)/r the one-way spreading and absorption, and k the ADC scale. The element n then
records A_n u(t − τ_n). Delays are exact per element (no plane-wave approximation) and computed in
float64.

The hot loops are compiled with numba: one pass per scatterer for the transmitter factor, and one
fused pass per (scatterer, element) pair that either returns (τ, A) or spreads A onto the sample
grid through a fractional-delay kernel. Threads split the receiver elements, so every channel is
accumulated in the same order whatever the number of threads (bit-identical results).
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .arrays import ElementArray
from .directivity import array_response, element_directivity
from .kernels import EXP_SMALL_LIMIT, cis_cycles, exp_small, sin_over
from .medium import Medium

__all__ = ["EchoModel", "transmit_factor", "arrivals", "spread_arrivals"]

_LN10_OVER_20 = np.log(10.0) / 20.0


@nb.njit(cache=True, inline="always", fastmath=True)
def _piston(dx, dy, dz, inv_r, ex0, ex1, ey0, ey1, hkw, hkh, baffle):
    """Far-field rectangular piston directivity towards (dx, dy, dz) at distance 1/inv_r."""
    if baffle and dz < 0.0:
        return 0.0
    ux = (dx * ex0 + dy * ex1) * inv_r
    uy = (dx * ey0 + dy * ey1) * inv_r
    return sin_over(hkw * ux) * sin_over(hkh * uy)


@nb.njit(cache=True, parallel=True, fastmath=True)
def _tx_far_field(px, py, pz, c, ex, ey, hkw, hkh, w, ref, inv_lam, baffle):
    """E_t(P) for every scatterer: Σ_e w_e D_e e^{−jk(R_e − R_T)} (R_T/R_e) / Σ w_e."""
    n_s = px.shape[0]
    n_e = c.shape[0]
    wsum = 0.0
    for e in range(n_e):
        wsum += w[e]
    out = np.empty(n_s, np.complex128)
    for s in nb.prange(n_s):
        rx = px[s] - ref[0]
        ry = py[s] - ref[1]
        rz = pz[s] - ref[2]
        r_ref = np.sqrt(rx * rx + ry * ry + rz * rz)
        acc_r = 0.0
        acc_i = 0.0
        for e in range(n_e):
            dx = px[s] - c[e, 0]
            dy = py[s] - c[e, 1]
            dz = pz[s] - c[e, 2]
            r = max(np.sqrt(dx * dx + dy * dy + dz * dz), 1e-9)
            inv_r = 1.0 / r
            d = _piston(dx, dy, dz, inv_r, ex[e, 0], ex[e, 1], ey[e, 0], ey[e, 1], hkw[e], hkh[e], baffle)
            # R_e − R_T without cancellation: (|a|² − |b|²)/(|a| + |b|)
            diff = ((ref[0] - c[e, 0]) * (dx + rx) + (ref[1] - c[e, 1]) * (dy + ry)
                    + (ref[2] - c[e, 2]) * (dz + rz)) / (r + r_ref)
            sn, cs = cis_cycles(-diff * inv_lam)
            amp = w[e] * d * r_ref * inv_r
            acc_r += amp * cs
            acc_i += amp * sn
        out[s] = complex(acc_r, acc_i) / wsum
    return out


@nb.njit(cache=True, inline="always", fastmath=True)
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
        are = _piston(dx, dy, dz, inv_r, ex0, ex1, ey0, ey1, hkw, hkh, baffle) * g
        aim = 0.0
    # (fre + j fim)(are + j aim)(cs + j sn)
    pr = fre * are - fim * aim
    pi = fre * aim + fim * are
    return path * inv_c, pr * cs - pi * sn, pr * sn + pi * cs


@nb.njit(cache=True, parallel=True, fastmath=True)
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


@nb.njit(cache=True, parallel=True, fastmath=True)
def _spread(px, py, pz, fre, fim, r1, c, ex, ey, hkw, hkh, d_in, use_d, inv_c, inv_lam, alpha,
            small_abs, spreading, baffle, table, t0, fs, q0, n_out):
    """Accumulate every arrival onto its channel's delta train through the kernel table.

    ``table[i, j]`` is the kernel at tap j for fractional offset i / (rows − 1); taps land on
    samples floor(μ) − L/2 + 1 + j with μ = (τ − t0) fs + q0. One thread per channel, scatterers
    in the given order: the sums do not depend on the number of threads.
    """
    n_s, n_r = px.shape[0], c.shape[0]
    n_phase = table.shape[0] - 1
    taps = table.shape[1]
    half = taps // 2
    out_r = np.zeros((n_r, n_out))
    out_i = np.zeros((n_r, n_out))
    lo = float(half)
    hi = float(n_out - half)
    for n in nb.prange(n_r):
        row_r = out_r[n]
        row_i = out_i[n]
        cx, cy, cz = c[n, 0], c[n, 1], c[n, 2]
        ex0, ex1, ey0, ey1 = ex[n, 0], ex[n, 1], ey[n, 0], ey[n, 1]
        kw, kh = hkw[n], hkh[n]
        for s in range(n_s):
            d = d_in[s, n] if use_d else 0j
            tau, ar, ai = _pair(px[s], py[s], pz[s], fre[s], fim[s], r1[s], cx, cy, cz, ex0, ex1,
                                ey0, ey1, kw, kh, d.real, d.imag, use_d, inv_c, inv_lam, alpha,
                                small_abs, spreading, baffle)
            mu = (tau - t0) * fs + q0
            if mu < lo or mu >= hi:
                continue  # wholly outside the record (q0 leaves room for the pulse)
            m0 = int(mu)
            x = (mu - m0) * n_phase
            i = min(int(x), n_phase - 1)
            w = x - i
            base = m0 - half + 1
            for j in range(taps):
                h = table[i, j] + w * (table[i + 1, j] - table[i, j])
                row_r[base + j] += ar * h
                row_i[base + j] += ai * h
    return out_r, out_i


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
        k: ADC counts per unit pressure.
    fidelity : {"far_field", "huygens"}
    subdivisions : (int, int)
    baffle, spreading, absorption : bool
    """

    transmitter: ElementArray
    receiver: ElementArray
    medium: Medium
    center_frequency_hz: float = 420_375.0
    scale_counts: float = 1.0
    fidelity: str = "far_field"
    subdivisions: tuple = (4, 4)
    baffle: bool = True
    spreading: bool = True
    absorption: bool = True

    @property
    def wavenumber_rad_m(self) -> float:
        return self.medium.wavenumber_rad_m(self.center_frequency_hz)

    def _rx_args(self, p):
        """Receiver-side arguments of the compiled kernels for scatterers ``p`` (S, 3)."""
        rx = self.receiver
        ex, ey = rx.local_axes
        k = self.wavenumber_rad_m
        if self.fidelity == "huygens":
            d_in = element_directivity(rx, p, wavenumber_rad_m=k, fidelity="huygens",
                                       subdivisions=self.subdivisions, baffle=self.baffle)
        else:
            d_in = np.zeros((1, 1), np.complex128)
        alpha = (self.medium.absorption_db_per_m * _LN10_OVER_20
                 if self.absorption and self.medium.absorption_db_per_m > 0 else 0.0)
        # |r2 − r1| <= |R_n − T|, so this bound decides if the cheap exponential is exact
        reach = float(np.max(np.linalg.norm(rx.center_m - self.transmitter.phase_center_m, axis=1)))
        return (np.ascontiguousarray(rx.center_m), np.ascontiguousarray(ex[:, :2]),
                np.ascontiguousarray(ey[:, :2]), 0.5 * k * rx.width_m, 0.5 * k * rx.height_m,
                np.ascontiguousarray(d_in, np.complex128), self.fidelity == "huygens",
                1.0 / self.medium.sound_speed_m_s,
                self.center_frequency_hz / self.medium.sound_speed_m_s, alpha,
                alpha * reach <= EXP_SMALL_LIMIT, self.spreading, self.baffle)


def _positions(positions) -> np.ndarray:
    p = np.ascontiguousarray(np.asarray(positions, float).reshape(-1, 3))
    if not np.all(np.isfinite(p)):
        raise ValueError("scatterer positions must be finite")
    return p


def transmit_factor(model: EchoModel, positions_m, strength):
    """Per-scatterer factor k·q·E_t(P)·g(r1) and the transmit leg r1.

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
    q = np.asarray(strength, complex).reshape(-1)
    tx = model.transmitter
    ref = tx.phase_center_m
    k = model.wavenumber_rad_m
    if model.fidelity == "huygens":
        e_t = array_response(tx, p, wavenumber_rad_m=k, fidelity="huygens",
                             subdivisions=model.subdivisions, baffle=model.baffle, reference_m=ref)
    else:
        ex, ey = tx.local_axes
        e_t = _tx_far_field(p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy(),
                            np.ascontiguousarray(tx.center_m), np.ascontiguousarray(ex[:, :2]),
                            np.ascontiguousarray(ey[:, :2]), 0.5 * k * tx.width_m,
                            0.5 * k * tx.height_m, tx.weight, ref,
                            model.center_frequency_hz / model.medium.sound_speed_m_s, model.baffle)
    r1 = np.linalg.norm(p - ref, axis=1)
    g1 = model.medium.one_way_gain(r1, spreading=model.spreading, absorption=model.absorption)
    return model.scale_counts * q * e_t * g1, r1


def _kernel_inputs(model, positions_m, strength, order=None):
    p = _positions(positions_m)
    f_s, r1 = transmit_factor(model, p, strength)
    alpha_args = model._rx_args(p)
    alpha = alpha_args[9]
    if alpha:
        f_s = f_s * np.exp(-alpha * r1)  # the receive leg's absorption relative to the transmit leg
    if order is not None:
        p, f_s, r1 = p[order], f_s[order], r1[order]
        if alpha_args[6]:  # huygens directivities follow their scatterers
            alpha_args = alpha_args[:5] + (alpha_args[5][order],) + alpha_args[6:]
    cols = (np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
            np.ascontiguousarray(p[:, 2]), np.ascontiguousarray(f_s.real),
            np.ascontiguousarray(f_s.imag), np.ascontiguousarray(r1))
    return cols + alpha_args


def arrivals(model: EchoModel, positions_m, strength):
    """Delay and complex amplitude of every (scatterer, receiver element) arrival.

    Returns
    -------
    tau_s : ndarray, shape (S, N_rx), float64
        Two-way delays (s) from the transmitter's phase centre to each element.
    amplitude : ndarray, shape (S, N_rx), complex128
        A_n in ADC counts, carrier phase e^{−j2πf0τ} included.
    """
    return _arrivals(*_kernel_inputs(model, positions_m, strength))


def spread_arrivals(model: EchoModel, positions_m, strength, *, table, t0_s, rate_hz, q0, n_out):
    """The channels' fractional-delay delta trains, shape (N_rx, n_out), complex128.

    Scatterers are visited in order of range (a stable sort), so the delta trains are written
    nearly sequentially; the order is fixed by the scene, never by the thread count.
    """
    p = _positions(positions_m)
    order = np.argsort(np.linalg.norm(p, axis=1), kind="stable")
    args = _kernel_inputs(model, p, strength, order)
    out_r, out_i = _spread(*args, np.ascontiguousarray(table), float(t0_s), float(rate_hz),
                           float(q0), int(n_out))
    return out_r + 1j * out_i
