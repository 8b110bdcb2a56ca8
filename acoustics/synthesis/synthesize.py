"""Per-element echo synthesis: arrivals x transmit pulse -> complex baseband samples.

One function, two methods (the accuracy knob ``effects.synthesis``):

``exact`` (the reference)
    evaluates every arrival's envelope A u(t_i − τ) at every sample t_i it touches.
``fast``
    spreads each arrival onto a grid ``oversampling`` times finer than the samples with a
    Kaiser-windowed sinc fractional-delay kernel of ``kernel_length`` taps (a band-limited
    impulse at τ), convolves each channel with the pulse sampled on that grid by one FFT, and
    keeps every ``oversampling``-th sample. The FFT is long enough for the convolution to be
    linear: a late echo never wraps round to the start of the record.

Why it works: the pulse occupies |f| ≲ B/2, so the kernel only has to be exact for |f| < B/2 and
may do anything between B/2 and U·fs − B/2; its Kaiser β is chosen for that transition band. What
no band-limited method can reproduce is the part of the envelope's spectrum beyond the grid's
Nyquist frequency, which ``exact`` aliases into its samples (the sqrt-Hann taper's kinks at the
pulse ends put it at about −62 dB for fs = 45.455 kHz); the finer grid pushes that floor down
(−70 dB at U = 2, −82 dB at U = 4). docs/accuracy.md has the table.
"""
from __future__ import annotations

from functools import lru_cache

import numba as nb
import numpy as np
import scipy.fft as sfft
from scipy.special import i0

from acoustics.synthesis.arrivals import EchoModel, arrivals, spread_arrivals
from acoustics.sonar.pulse import Pulse

__all__ = ["METHODS", "DOPPLER_METHODS", "fractional_delay_table", "synthesize"]

METHODS = ("fast", "exact")
#: how the fast synthesis shifts Doppler echoes: a bank of a few replicas interpolated in
#: frequency (acoustics/synthesis/doppler_bank.py), or the older grid of shifted replicas
DOPPLER_METHODS = ("bank", "bins")
_TABLE_PHASES = 2048  # linear interpolation between phases: error < 1e-7 of the peak
#: a Doppler grid frequency costs about as much as this many echoes synthesised exactly (a
#: forward FFT of 16 channels vs 16 x 320 envelope samples each; measured in
#: benchmarks/accuracy.py, "within-ping motion")
_EXACT_PER_BIN = 3.0


def _kaiser_beta(attenuation_db: float) -> float:
    a = attenuation_db
    if a > 50:
        return 0.1102 * (a - 8.7)
    if a > 21:
        return 0.5842 * (a - 21) ** 0.4 + 0.07886 * (a - 21)
    return 0.0


@lru_cache(maxsize=32)
def fractional_delay_table(taps: int, transition: float, phases: int = _TABLE_PHASES):
    """Windowed-sinc fractional-delay kernel, tabulated.

    Parameters
    ----------
    taps : int
        Kernel length L (even, >= 2).
    transition : float
        Width of the free band between the signal band and its first image, as a fraction of the
        sampling rate: (fs − B_signal)/fs.
    phases : int
        Rows of the table (fractional offsets 0, 1/phases, ..., 1).

    Returns
    -------
    ndarray, shape (phases + 1, taps)
        ``table[i, j]`` = h(j − L/2 + 1 − i/phases): the kernel weight of tap j for a delay whose
        fractional part is i/phases; h = sinc · Kaiser window of half-width L/2.
    """
    if taps < 2 or taps % 2:
        raise ValueError(f"kernel length must be an even number >= 2, got {taps}")
    transition = float(np.clip(transition, 0.02, 1.0))
    atten = 2.285 * (taps - 1) * 2 * np.pi * transition + 8.0
    beta = _kaiser_beta(atten)
    frac = np.arange(phases + 1)[:, None] / phases
    x = np.arange(taps)[None, :] - taps // 2 + 1 - frac
    half = taps / 2
    window = i0(beta * np.sqrt(np.clip(1 - (x / half) ** 2, 0, 1))) / i0(beta)
    table = np.sinc(x) * window
    table.flags.writeable = False
    return table


def synthesize(model: EchoModel, positions_m, strength, *, pulse: Pulse, rate_hz: float,
               n_samples: int, t0_s: float = 0.0, method: str = "fast", kernel_length: int = 8,
               oversampling: int = 2, receive_positions_m=None, doppler_hz=None,
               doppler_bin_hz: float = 5.0, doppler_method: str = "bank",
               doppler_error_db: float = -50.0):
    """Complex baseband samples of every receiver element for a set of point scatterers.

    Parameters
    ----------
    model : EchoModel
        Arrays, medium, fidelity and ADC scale.
    positions_m : array_like, shape (S, 3)
        Scatterers (m) in the sonar frame. S = 0 gives silence.
    strength : array_like, shape (S,)
        Complex backscatter amplitude ρ e^{jφ} (m).
    pulse : Pulse
    rate_hz : float
        Sampling rate fs (Hz).
    n_samples : int
        Samples per channel N.
    t0_s : float
        Time (s) of sample 0 after the start of transmission.
    method : {"fast", "exact"}
    kernel_length : int
        Fractional-delay kernel taps on the fine grid (``fast`` only).
    oversampling : int
        Fine-grid factor U >= 1 (``fast`` only).
    receive_positions_m : array_like, shape (S, 3), optional
        Start of each receive leg when it differs from the transmit leg's end (the image point of
        a path that bounces on its way back); default the same points.
    doppler_hz : array_like, shape (S,), optional
        Two-way Doppler shift f_d = 2 v_r f0 / c of each scatterer (Hz; v_r its speed towards
        the sonar): the echo is u(t − τ) e^{j2π f_d (t − τ)} e^{−j2πf0τ} (narrowband: the
        carrier shifts, the envelope's 10⁻³ compression is neglected). None: no Doppler.
    doppler_bin_hz : float
        ``fast`` only: shifted scatterers share Doppler-shifted replicas on a grid of this step,
        each split linearly between its two neighbours; the phase error over a pulse of length T
        is at most (π Δf T)²/2 (docs/accuracy.md, "within-ping motion"). When the shifted
        scatterers are fewer than about 3 per occupied grid frequency they are synthesised
        exactly instead (cheaper, and the reference). ``doppler_method="bins"`` only.
    doppler_method : {"bank", "bins"}
        ``fast`` only: ``bank`` (default) spreads each shifted scatterer once, onto a few trains
        convolved with replicas at Chebyshev nodes of the ping's shifts, the LFM's
        range–Doppler coupling taken out first (acoustics/synthesis/doppler_bank.py); ``bins``
        the grid of ``doppler_bin_hz``.
    doppler_error_db : float
        ``bank`` only: the bank takes the fewest nodes whose worst error over the ping's shifts
        (re the pulse, L2) is below this (docs/accuracy.md, "Doppler bank").

    Returns
    -------
    ndarray, shape (N_rx, N), complex128
        ADC counts (before noise and quantisation).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    p = np.asarray(positions_m, float).reshape(-1, 3)
    q = np.asarray(strength, complex).reshape(-1)
    if p.shape[0] != q.shape[0]:
        raise ValueError("positions_m and strength must describe the same scatterers")
    n_rx = model.receiver.n_elements
    if p.shape[0] == 0:
        return np.zeros((n_rx, n_samples), complex)
    prx = None if receive_positions_m is None else np.asarray(receive_positions_m, float).reshape(-1, 3)
    fd = None
    if doppler_hz is not None:
        fd = np.asarray(doppler_hz, float).reshape(-1)
        if fd.shape[0] != p.shape[0] or not np.all(np.isfinite(fd)):
            raise ValueError("doppler_hz must be finite, one per scatterer")
        if not np.any(fd):
            fd = None
    if method == "exact":
        return _exact(model, p, q, pulse, rate_hz, n_samples, t0_s, prx, fd)
    if int(oversampling) < 1:
        raise ValueError(f"oversampling must be >= 1, got {oversampling}")
    if fd is None:
        return _fast(model, p, q, pulse, rate_hz, n_samples, t0_s, kernel_length, int(oversampling), prx)
    if doppler_method not in DOPPLER_METHODS:
        raise ValueError(f"doppler_method must be one of {DOPPLER_METHODS}, got {doppler_method!r}")
    if doppler_method == "bank":
        return _fast_bank(model, p, q, pulse, rate_hz, n_samples, t0_s, kernel_length,
                          int(oversampling), prx, fd, float(doppler_error_db))
    if not doppler_bin_hz > 0:
        raise ValueError(f"doppler_bin_hz must be > 0, got {doppler_bin_hz}")
    # Doppler bins: each shifted scatterer split linearly between the two replicas shifted by
    # the grid frequencies around its own; the bins' spectra add up before one inverse FFT
    moving = np.flatnonzero(fd != 0)
    still = np.flatnonzero(fd == 0)
    pos = fd[moving] / doppler_bin_hz
    lo = np.floor(pos).astype(np.int64)
    frac = pos - lo
    bins = np.unique(np.concatenate([lo, lo + 1]))
    groups = [(0.0, still, np.ones(still.size))] if still.size else []
    if moving.size < _EXACT_PER_BIN * bins.size:
        # few shifted echoes for the grid frequencies they occupy: each one exactly is cheaper
        # (and is the reference)
        part = _exact(model, p[moving], q[moving], pulse, rate_hz, n_samples, t0_s,
                      None if prx is None else prx[moving], fd[moving])
        if not groups:
            return part
        return part + _fast(model, p, q, pulse, rate_hz, n_samples, t0_s, kernel_length,
                            int(oversampling), prx, groups=groups)
    for b in bins:
        w = np.where(lo == b, 1.0 - frac, 0.0) + np.where(lo + 1 == b, frac, 0.0)
        k = np.flatnonzero(w > 0)
        if k.size:
            groups.append((float(b) * doppler_bin_hz, moving[k], w[k]))
    return _fast(model, p, q, pulse, rate_hz, n_samples, t0_s, kernel_length, int(oversampling),
                 prx, groups=groups)


def _fast_bank(model, p, q, pulse, fs, n, t0, taps, up, prx, fd, error_db):
    """Still scatterers through the plain replica, shifted ones through the bank, under one
    inverse FFT (acoustics/synthesis/doppler_bank.py)."""
    from acoustics.synthesis.doppler_bank import bank_nodes, synthesize_bank
    moving = np.flatnonzero(fd != 0)
    n_nodes = bank_nodes(pulse, fs * up, fd[moving], error_db).size
    if moving.size < _EXACT_PER_BIN * n_nodes:
        # a few shifted echoes: each exactly is cheaper (and the reference)
        still = np.flatnonzero(fd == 0)
        part = _exact(model, p[moving], q[moving], pulse, fs, n, t0,
                      None if prx is None else prx[moving], fd[moving])
        if not still.size:
            return part
        return part + _fast(model, p, q, pulse, fs, n, t0, taps, up, prx,
                            groups=[(0.0, still, np.ones(still.size))])
    return synthesize_bank(model, p, q, fd, pulse, fs, n, t0, taps, up, prx, error_db,
                           fractional_delay_table, _even_fast_len, _every_up_th)


def _exact(model, p, q, pulse, fs, n, t0, prx=None, fd=None):
    tau, amp = arrivals(model, p, q, receive_positions_m=prx)
    n_rx = tau.shape[1]
    m = pulse.n_samples(fs) + 1
    out_r = np.zeros(n_rx * n)
    out_i = np.zeros(n_rx * n)
    tau_f = tau.T.ravel()                     # channel-major, (N_rx * S,)
    amp_f = amp.T.ravel()
    fd_f = np.tile(fd, n_rx) if fd is not None else None
    chan = np.repeat(np.arange(n_rx), tau.shape[0])
    first = np.ceil((tau_f - t0) * fs - 1e-9).astype(np.int64)  # first sample at t >= τ
    keep = (first < n) & (first + m > 0)
    tau_f, amp_f, chan, first = tau_f[keep], amp_f[keep], chan[keep], first[keep]
    if fd_f is not None:
        fd_f = fd_f[keep]
    step = max(1, 4_000_000 // m)
    offs = np.arange(m)
    for s in range(0, tau_f.size, step):
        idx = first[s:s + step, None] + offs
        t = t0 + idx / fs - tau_f[s:s + step, None]
        val = amp_f[s:s + step, None] * pulse.envelope(t)
        if fd_f is not None:
            val = val * np.exp(2j * np.pi * fd_f[s:s + step, None] * t)
        ok = (idx >= 0) & (idx < n) & (val != 0)
        flat = (chan[s:s + step, None] * n + idx)[ok]
        out_r += np.bincount(flat, weights=val.real[ok], minlength=n_rx * n)
        out_i += np.bincount(flat, weights=val.imag[ok], minlength=n_rx * n)
    return (out_r + 1j * out_i).reshape(n_rx, n)


def _fast(model, p, q, pulse, fs, n, t0, taps, up, prx=None, groups=None):
    """``groups``: (shift_hz, indices, weights) of Doppler-binned scatterers, each convolved with
    the replica shifted by shift_hz; None: one group, unshifted. A Doppler group whose echoes
    span a short stretch of the record is convolved over that stretch alone (overlap-add)."""
    fine = fs * up
    replica = _replica(pulse, fine)
    m = replica.size
    # room for an echo that starts up to a pulse length plus half a kernel before sample 0; a
    # whole number of output samples, so the output keeps every up-th fine sample from q0
    q0 = up * -(-(m + taps) // up)
    n_out = q0 + up * n + taps
    doppler = groups is not None
    if groups is None:
        groups = [(0.0, slice(None), 1.0)]
    widest = max(abs(g[0]) for g in groups)
    band = min(pulse.bandwidth_hz + 4.0 / pulse.duration_s + 2.0 * widest, 0.98 * fine)
    table = fractional_delay_table(int(taps), (fine - band) / fine)
    nfft = _even_fast_len(n_out + m - 1, up)  # linear, not circular, convolution
    spec = None
    rep_spec = {}
    acc = None
    if doppler:
        c = model.medium.sound_speed_m_s
        reach = max(float(np.max(np.linalg.norm(model.receiver.center_m, axis=1))),
                    float(np.linalg.norm(model.transmitter.phase_center_m)))
    for shift_hz, k, w in groups:
        rep = replica if not shift_hz else replica * np.exp(2j * np.pi * shift_hz * np.arange(m) / fine)
        pk, qk, rk = p[k], q[k] * w, None if prx is None else prx[k]
        if doppler:
            # the stretch of the fine grid this group's echoes can touch: two legs from the
            # sonar's origin, ± the arrays' reach, ± the kernel
            path = np.linalg.norm(pk, axis=1) + np.linalg.norm(pk if rk is None else rk, axis=1)
            g_lo = max(0, int(np.floor(((path.min() - 2 * reach) / c - t0) * fine + q0)) - taps - 2)
            g_hi = min(n_out, int(np.ceil(((path.max() + 2 * reach) / c - t0) * fine + q0)) + taps + 2)
            span = g_hi - g_lo
            if span <= 0:
                continue
            if 2 * (span + m) < n_out + m:
                delta = spread_arrivals(model, pk, qk, table=table, t0_s=t0 + (g_lo - q0) / fine,
                                        rate_hz=fine, q0=0, n_out=span, receive_positions_m=rk)
                nf = sfft.next_fast_len(span + m - 1)
                part = sfft.fft(delta, nf, axis=1, workers=-1)
                part *= sfft.fft(rep, nf)
                y = sfft.ifft(part, axis=1, workers=-1)[:, :span + m - 1]
                if acc is None:
                    acc = np.zeros((delta.shape[0], nfft), complex)
                acc[:, g_lo:g_lo + span + m - 1] += y
                continue
        # the trains come at the FFT's length (no padded copy), transformed in place; one
        # group is done with them before this thread's next synthesis: its work buffer
        delta = spread_arrivals(model, pk, qk, table=table, t0_s=t0, rate_hz=fine, q0=q0,
                                n_out=n_out, receive_positions_m=rk, length=nfft,
                                scratch=not doppler)
        part = sfft.fft(delta, axis=1, workers=-1, overwrite_x=True)
        if shift_hz not in rep_spec:
            rep_spec[shift_hz] = (_replica_spectrum(pulse, fine, nfft) if not shift_hz
                                  else sfft.fft(rep, nfft))
        if not doppler:
            # one group: the product with the pulse and the fold of the decimation in one
            # parallel pass (the same operations as _every_up_th's)
            return _decimated(_product_folded(part, rep_spec[shift_hz], up), q0 // up, n)
        part *= rep_spec[shift_hz]
        if spec is None:
            spec = part
        else:
            spec += part
    out = _every_up_th(spec, up, q0, n) if spec is not None else None
    if acc is not None:
        late = acc[:, q0:q0 + up * n:up]
        out = late if out is None else out + late
    if out is None:
        return np.zeros((model.receiver.n_elements, n), complex)
    return out


@lru_cache(maxsize=8)
def _replica(pulse: Pulse, rate_hz: float):
    """The pulse's replica at ``rate_hz``: the same every ping of a run (read-only)."""
    rep = pulse.replica(rate_hz)
    rep.flags.writeable = False
    return rep


@lru_cache(maxsize=8)
def _replica_spectrum(pulse: Pulse, rate_hz: float, nfft: int):
    """The FFT (length ``nfft``) of the pulse's replica at ``rate_hz``: the same every ping of a
    run (read-only)."""
    spec = sfft.fft(_replica(pulse, rate_hz), nfft)
    spec.flags.writeable = False
    return spec


def _even_fast_len(n: int, up: int) -> int:
    """The smallest FFT-friendly length ≥ n that ``up`` divides."""
    size = sfft.next_fast_len(n)
    while size % up:
        size = sfft.next_fast_len(size + 1)
    return size


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _product_folded(part, rep, up):
    """(part x rep) folded for :func:`_every_up_th`: Σ_r part[:, f + r M] rep[f + r M] / up with
    M = N / up, shape (channels, M); sums in the order of numpy's reduction, division of the
    real and imaginary parts (numba's complex / real would be a complex division)."""
    n_c, size = part.shape[0], part.shape[1] // up
    out = np.empty((n_c, size), np.complex128)
    for c in nb.prange(n_c):
        for f in range(size):
            acc = part[c, f] * rep[f]
            for r in range(1, up):
                acc += part[c, f + r * size] * rep[f + r * size]
            out[c, f] = complex(acc.real / up, acc.imag / up)
    return out


def _decimated(folded, start: int, n: int):
    """Samples start, ..., start + n − 1 of the inverse FFT of ``folded`` (channels, M)."""
    y = sfft.ifft(folded, axis=-1, workers=-1, overwrite_x=True)
    return y[..., start:start + n]


def _every_up_th(spec, up: int, q0: int, n: int):
    """Samples q0, q0 + up, ... (n of them) of the inverse FFT of ``spec`` (..., N), computed
    by one inverse FFT of length N/up: keeping every up-th sample folds the spectrum,
    x[up k] = IFFT_{N/up}(Σ_r X[f + r N/up])[k] / up — the same numbers, half the transform."""
    size = spec.shape[-1] // up
    folded = spec.reshape(spec.shape[:-1] + (up, size)).sum(axis=-2)
    folded /= up
    return _decimated(folded, q0 // up, n)
