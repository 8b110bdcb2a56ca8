"""Single-target detection by the echosounder criteria: echo length, phase deviation, beam
compensation, TS threshold and echo spacing.

A split-beam echosounder keeps an echo as one fish's (Soule et al. 1995, 1997; Ona 1999, ICES
CRR 235; Simrad EK60/EK80 and Echoview's single-target detection) when its envelope has the
length of one pulse, its phase (the arrival angle) is steady across it, it lies where the beam
can be compensated, its TS clears a threshold, and no other echo is close to it. ABACUS'
images give the same measures per detection, in the beam the detection lies in:

* **echo length**: the width of the matched-filter envelope |I(r)| between the points
  ``level_db`` (6 dB) below its peak, interpolated linearly between samples, divided by the
  same width of the range filter's own point response (the nominal, compressed pulse:
  :func:`nominal_echo_length_m`). One echo gives 1; two overlapping echoes a longer or,
  where they cancel, a shorter or split envelope.
* **phase deviation**: the standard deviation (deg, electrical) of the interferometric phase
  over the samples within those points, in both planes as a split-beam echosounder measures
  it (alongship and athwartship). Elevation: ψ_AB = arg(I_A I_B*), taken relative to the
  phase at the peak (no wrapping). Azimuth: the beam-domain peak of each sample (a parabola
  through the echo's beam and its two neighbours) expressed as the phase between the two
  halves of the receive subarray, ψ_split = k d_split Δ(sin θ), d_split half the aperture,
  the phase a split aperture would measure. One target's phases are the same along its echo;
  two targets at different angles pull them from one's to the other's along the overlap.
* **range phase deviation**: the standard deviation (deg) of the echo's own phase along range,
  arg(I(r) I(r_peak)*), over the same samples, in each imaged subarray (the mean of A's and
  B's). The matched filter's point response has one phase across its main lobe (the compressed
  pulse is real at baseband), so one echo's phase is flat; two echoes closer than the range
  resolution, with amplitudes a₁, a₂ e^{iφ} and ranges δ apart, sum to
  (a₁ + a₂e^{iφ}) p(r − r̄) − a₂e^{iφ} δ p′(r − r̄) + O(δ²): the quadrature part of the second
  term turns the phase along the echo by ≈ Im(a₂e^{iφ}/(a₁ + a₂e^{iφ})) δ p′/p, first order
  in δ where the envelope's broadening is second order. Two echoes in phase (φ ≈ 0) add to a
  single echo at their centroid, which nothing in the echo can tell apart.
* **the noise's share**: each sample of one channel carries a phase noise σ/|I| (rad, σ the
  image noise's Rayleigh scale); over the echo's samples its RMS is
  σ_1 = σ (mean 1/|I|²)^½, which bounds the standard deviation noise alone gives (the
  samples are correlated, and their mean is removed). ψ_AB carries both channels',
  σ (mean 1/|I_A|² + 1/|I_B|²)^½; the split-aperture phase of the beam-domain peak
  g_split σ_1 (:func:`split_phase_noise_gain`); the range phase σ_1. With
  ``phase_deviation_sigmas`` = k > 0 a limit L becomes (L² + (k σ_noise)²)^½ per candidate:
  the fixed limit bounds what the target may add, the noise adds in quadrature
  (:func:`phase_limit_deg`).
* **beam compensation**: one-way, half the two-way compensation at the located angles
  (processing/backscatter/target_strength.py).
* **echo spacing**: the range to the nearest other echo in the same beam (within one azimuth
  resolution), in nominal pulse lengths.

:func:`verdicts` applies the parameters of :class:`processing.settings.SingleTargetSettings`
(names and meanings of the SONAR-netCDF4 2.0 SingleTarget group) and names the first rule a
candidate fails, in the order of :data:`RULES`. Pure functions over arrays; the chain
(:meth:`processing.pipeline.RecordChain.target_detection`) feeds them the images.
"""
from __future__ import annotations

import numpy as np

from typing import NamedTuple

__all__ = ["RULES", "EchoShape", "nominal_echo_length_m", "echo_shape", "echo_spacing",
           "split_phase_noise_gain", "phase_limit_deg", "verdicts"]

#: the rules, in the order they are tested; a rejected candidate names the first it fails
RULES = ("sidelobe", "image_edge", "TS_threshold", "minimum_echo_duration", "maximum_echo_duration",
         "maximum_phase_deviation", "maximum_range_phase_deviation", "gain_compensation",
         "minimum_echo_spacing")


def nominal_echo_length_m(response, rate_hz: float, sound_speed_m_s: float, *, level_db: float = 6.0,
                          upsample: int = 32) -> float:
    """Width (m of range) of the range filter's point response between its points ``level_db``
    below the peak: the echo length of one point target, the normaliser of echo lengths.

    Parameters
    ----------
    response : array_like, shape (nfft,)
        The compressed pulse's spectrum on the filter's FFT grid
        (:attr:`processing.imaging.compression.RangeFilter.response`).
    rate_hz, sound_speed_m_s : float
    level_db : float
    upsample : int
        Zero-padding factor of the inverse FFT (the width is read off a fine grid).

    Returns
    -------
    float
    """
    env = np.abs(_fine_pulse(np.asarray(response, float), upsample))
    lo, hi = _crossings(env, int(np.argmax(env)), 10.0 ** (-level_db / 20.0))
    return float((hi - lo) / (rate_hz * upsample) * sound_speed_m_s / 2.0)


def moving_echo_range_phase_deg(replica, filter_spectrum, rate_hz: float, doppler_hz: float, *,
                                level_db: float = 6.0, upsample: int = 8) -> float:
    """The range phase deviation (deg) that one point echo shows when it is Doppler shifted:
    what a lone fish moving radially adds to the measure of :func:`echo_shape`.

    A target closing at radial speed v returns the pulse shifted by f_d = 2 v f₀ / c; through
    the matched filter of the unshifted replica its compressed echo is the pulse's ambiguity
    function at that shift, whose phase runs along range (for a linear chirp, linearly: the
    range–Doppler coupling), so a moving single echo reads as two echoes closer than the
    resolution would. Computed here from the record's own replica and filter.

    Parameters
    ----------
    replica : array_like of complex, shape (M,)
        The transmitted pulse at the record's sampling rate (complex baseband).
    filter_spectrum : array_like of complex, shape (nfft,)
        The range filter's U*(f) W(f) / G (:attr:`processing.imaging.compression.RangeFilter.spectrum`).
    rate_hz : float
        Sampling rate (Hz).
    doppler_hz : float
        The echo's Doppler shift f_d (Hz).
    level_db : float
        The echo's ends, as in :func:`echo_shape`.
    upsample : int
        Zero-padding factor of the inverse FFT (the measure is taken on a fine grid).

    Returns
    -------
    float
        Standard deviation (deg) of the unwrapped phase between the −``level_db`` points,
        relative to the peak's; 0 for no shift.
    """
    rep = np.asarray(replica, complex)
    h = np.asarray(filter_spectrum, complex)
    n = h.size
    t_s = np.arange(rep.size) / float(rate_hz)
    out = _fine_pulse(np.fft.fft(rep * np.exp(2j * np.pi * float(doppler_hz) * t_s), n) * h, upsample)
    env = np.abs(out)
    peak = int(np.argmax(env))
    lo, hi = _crossings(env, peak, 10.0 ** (-level_db / 20.0))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return float("nan")
    rows = np.arange(int(np.ceil(lo)), int(np.floor(hi)) + 1)
    if rows.size < 2:
        return 0.0
    return float(np.degrees(np.std(np.unwrap(np.angle(out[rows] * np.conj(out[peak]))))))


def _fine_pulse(spectrum, upsample: int) -> np.ndarray:
    """The compressed pulse of a spectrum on the filter's FFT grid, on a grid ``upsample`` times
    finer (zero-padded between its positive and negative frequencies), its peak lag centred."""
    n = spectrum.size
    big = np.zeros(n * upsample, spectrum.dtype)
    h = n // 2
    big[:h], big[n * upsample - (n - h):] = spectrum[:h], spectrum[h:]
    return np.fft.fftshift(np.fft.ifft(big))


def _crossings(env, i, fraction):
    """Fractional indices where ``env`` first falls below ``fraction`` x env[i] each side of i;
    NaN on a side where it never does."""
    level = fraction * env[i]
    below = np.flatnonzero(env[:i] < level)
    if below.size:
        j = below[-1]                       # env[j] < level <= env[j + 1]
        lo = j + (level - env[j]) / (env[j + 1] - env[j])
    else:
        lo = np.nan
    below = np.flatnonzero(env[i + 1:] < level)
    if below.size:
        j = i + 1 + below[0]                # env[j - 1] >= level > env[j]
        hi = j - 1 + (env[j - 1] - level) / (env[j - 1] - env[j])
    else:
        hi = np.nan
    return lo, hi


class EchoShape(NamedTuple):
    """The measures of one echo in one beam (:func:`echo_shape`); NaN where not measured."""

    length_m: float
    """Echo length (m) between the envelope's −level_db points."""
    phase_deviation_deg: float
    """Standard deviation of ψ_AB over the samples within the ends (deg, electrical)."""
    beam_offset_sd: float
    """Standard deviation of the beam-domain peak over the same samples (beam steps)."""
    range_phase_deviation_deg: float
    """Standard deviation of the echo's own phase along range (deg), the mean over the
    subarrays' images given."""
    noise_phase_deg: float
    """RMS over the samples of σ/|I| (deg): the phase spread one channel's noise gives."""
    noise_phase_ab_deg: float
    """RMS over the samples of σ (1/|I_A|² + 1/|I_B|²)^½ (deg): the noise's spread of ψ_AB."""


def echo_shape(envelope, row: int, *, range_step_m: float, level_db: float = 6.0, cross=None,
               neighbours=None, profiles=None, noise_sigma: float | None = None,
               search_rows: int = 2) -> EchoShape:
    """Echo length, phase deviations and the noise's share of them, of one echo in one beam.

    Parameters
    ----------
    envelope : array_like, shape (n_range,)
        |I_A| along range in the echo's beam (counts).
    row : int
        The detection's row; the peak is the largest sample within ``search_rows`` of it.
    range_step_m : float
        Range step of the rows (m).
    level_db : float
        The echo's ends: where the envelope falls this far below the peak.
    cross : array_like of complex, shape (n_range,), optional
        I_A I_B* along the same beam (interferometric mode), for the phase deviation.
    neighbours : array_like, shape (n_range, 2), optional
        |I_A| in the beams either side (lower, higher beam angle), for the azimuth deviation.
    profiles : array_like of complex, shape (n_range, n_images), optional
        The complex images along the same beam (A, and B in interferometric mode), for the
        range phase deviation.
    noise_sigma : float, optional
        The image noise's Rayleigh scale σ (counts; E|n|² = 2σ²), for the noise's share;
        NaN or None: not given (the noise terms are NaN).

    Returns
    -------
    EchoShape
        All NaN when the echo runs off the image (its end is not seen); each phase measure NaN
        without its input.
    """
    nan = EchoShape(*([np.nan] * 6))
    env = np.asarray(envelope, float)
    n = env.size
    a, b = max(0, row - search_rows), min(n, row + search_rows + 1)
    peak = a + int(np.argmax(env[a:b]))
    if not env[peak] > 0:
        return nan
    lo, hi = _crossings(env, peak, 10.0 ** (-level_db / 20.0))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return nan
    length = float((hi - lo) * range_step_m)
    rows = np.arange(int(np.ceil(lo)), int(np.floor(hi)) + 1)
    phase_sd = offset_sd = range_sd = noise1 = noise_ab = np.nan
    if cross is not None:
        c = np.asarray(cross, complex)
        ref = c[peak]
        if rows.size < 2 or ref == 0:
            phase_sd = 0.0
        else:
            # relative to the phase at the peak: the deviations of one echo are small, no wrapping
            phase_sd = float(np.degrees(np.std(np.angle(c[rows] * np.conj(ref)))))
    if neighbours is not None:
        from processing.detection.peaks import refine
        nb = np.asarray(neighbours, float)
        off, _ = refine(nb[rows, 0], env[rows], nb[rows, 1])
        offset_sd = float(np.std(off)) if rows.size >= 2 else 0.0
    if profiles is not None:
        pr = np.asarray(profiles, complex).reshape(n, -1)
        rel = pr[rows] * np.conj(pr[peak])[None, :]
        # unwrapped along range: a phase that runs past ±180° across the echo is not small
        range_sd = (float(np.degrees(np.mean(np.std(np.unwrap(np.angle(rel), axis=0), axis=0))))
                    if rows.size >= 2 else 0.0)
    if noise_sigma is not None and np.isfinite(noise_sigma):
        inv_a = 1.0 / np.maximum(env[rows], np.finfo(float).tiny) ** 2
        noise1 = float(np.degrees(noise_sigma * np.sqrt(np.mean(inv_a))))
        if cross is not None:
            # |I_B| = |I_A I_B*| / |I_A|
            mag_b = np.abs(np.asarray(cross, complex)[rows]) / np.maximum(env[rows], np.finfo(float).tiny)
            inv_b = 1.0 / np.maximum(mag_b, np.finfo(float).tiny) ** 2
            noise_ab = float(np.degrees(noise_sigma * np.sqrt(np.mean(inv_a + inv_b))))
    return EchoShape(length, phase_sd, offset_sd, range_sd, noise1, noise_ab)


def split_phase_noise_gain(x_m, weights, beam_step_u: float, wavelength_m: float,
                           split_m: float) -> float:
    """The noise's spread of the split-aperture phase of the beam-domain peak, in units of one
    channel's phase noise σ/|I|.

    The peak's offset is the parabola through the magnitudes of the echo's beam and its two
    neighbours, off = (m₋ − m₊) / (2 (m₋ − 2m₀ + m₊)) beam steps. Near the beam's centre the
    noise moves it by the difference of the neighbours' in-phase noises (variance
    2σ²(1 − ρ₂), ρ₂ the correlation of beams two steps apart, Σw² e^{ik x 2Δu} / Σw²) over
    twice the curvature |m₋ − 2m₀ + m₊| = |I| (2 − 2P(Δu)), P the normalised beam pattern one
    step off; the split phase is k d_split Δu off.

    Parameters
    ----------
    x_m : array_like, shape (n_elements,)
        The imaged subarray's element positions along the array (m).
    weights : array_like, shape (n_elements,)
        The beamformer's spatial window.
    beam_step_u : float
        Step between beams in sin θ.
    wavelength_m, split_m : float
        Wavelength and the distance between the two halves' centres (m).

    Returns
    -------
    float
        g_split (dimensionless, ≥ 0; NaN for fewer than two elements or no curvature).
    """
    x = np.asarray(x_m, float)
    w = np.asarray(weights, float)
    if x.size < 2 or not np.sum(w) > 0:
        return float("nan")
    k = 2 * np.pi / wavelength_m
    xc = x - np.sum(w * x) / np.sum(w)
    pattern = abs(np.sum(w * np.exp(1j * k * xc * beam_step_u))) / np.sum(w)
    rho2 = float(np.real(np.sum(w ** 2 * np.exp(2j * k * xc * beam_step_u))) / np.sum(w ** 2))
    curvature = 2.0 - 2.0 * pattern
    if not curvature > 0:
        return float("nan")
    return float(k * split_m * beam_step_u * np.sqrt(max(2.0 * (1.0 - rho2), 0.0)) / (2.0 * curvature))


def phase_limit_deg(limit_deg, noise_deg, sigmas: float, motion_deg: float = 0.0):
    """The limit of a phase rule at each candidate: (L² + D² + (k σ_noise)²)^½ — the fixed limit
    bounds what the target may add, the motion D what a single echo of the fastest allowed
    radial speed shows (the range phase only: :func:`moving_echo_range_phase_deg`), the noise
    adds in quadrature; L where neither is known (NaN) or k = 0 and D = 0 (the fixed limit
    alone: the EK60/Echoview convention).

    Parameters
    ----------
    limit_deg : float or None
        The fixed limit L (deg); None: the rule is not applied (all inf).
    noise_deg : array_like, shape (n,)
        The noise's spread σ_noise of the measure at each candidate (deg).
    sigmas : float
        k.
    motion_deg : float
        D (deg); NaN counts as 0.

    Returns
    -------
    ndarray, shape (n,)
    """
    noise = np.asarray(noise_deg, float)
    if limit_deg is None:
        return np.full(noise.shape, np.inf)
    extra = np.where(np.isfinite(noise), float(sigmas) * noise, 0.0)
    d = float(motion_deg) if np.isfinite(motion_deg) else 0.0
    return np.sqrt(float(limit_deg) ** 2 + d ** 2 + extra ** 2)


def echo_spacing(ping, range_m, azimuth_rad, candidate, *, azimuth_resolution_rad: float):
    """Range (m) to the nearest other candidate echo of the same ping in the same beam (within
    one azimuth resolution); inf where there is none.

    Parameters
    ----------
    ping : array_like of int, shape (n,)
    range_m, azimuth_rad : array_like, shape (n,)
    candidate : array_like of bool, shape (n,)
        Which detections are echoes to space (not another's sidelobe).

    Returns
    -------
    ndarray, shape (n,)
    """
    p = np.asarray(ping, int)
    r = np.asarray(range_m, float)
    az = np.asarray(azimuth_rad, float)
    cand = np.asarray(candidate, bool)
    out = np.full(p.size, np.inf)
    for q in np.unique(p):
        k = np.flatnonzero((p == q) & cand)
        if k.size < 2:
            continue
        dr = np.abs(r[k][:, None] - r[k][None, :])
        same_beam = np.abs(az[k][:, None] - az[k][None, :]) <= azimuth_resolution_rad
        dr = np.where(same_beam & ~np.eye(k.size, dtype=bool), dr, np.inf)
        out[k] = dr.min(axis=1)
    return out


def verdicts(*, sidelobe, ts_comp_db, echo_length, phase_deviation_deg, compensation_db,
             spacing, settings, phase_noise_deg=None, range_phase_deviation_deg=None,
             range_phase_noise_deg=None, range_phase_motion_deg: float = 0.0):
    """The first rule of :data:`RULES` each candidate fails ("" when it is a single target).

    Parameters
    ----------
    sidelobe : array_like of bool, shape (n,)
        Another detection's sidelobe or ghost.
    ts_comp_db : array_like, shape (n,)
        Compensated TS (dB re 1 m²); NaN fails ``gain_compensation`` (beyond the compensable
        beam) unless an earlier rule fails.
    echo_length : array_like, shape (n,)
        Normalised echo length; NaN: the echo runs off the image (``image_edge``).
    phase_deviation_deg : array_like, shape (n,) or (n_planes, n)
        The phase deviations (deg, electrical) of each plane (elevation ψ_AB, azimuth's split
        phase); a candidate fails when any plane exceeds its limit. NaN: no phase in that plane,
        not tested there.
    phase_noise_deg : array_like, same shape as ``phase_deviation_deg``, optional
        The noise's spread of each (deg; :class:`EchoShape`, :func:`split_phase_noise_gain`);
        with ``settings.phase_deviation_sigmas`` it widens the limit (:func:`phase_limit_deg`).
    range_phase_deviation_deg, range_phase_noise_deg : array_like, shape (n,), optional
        The range phase deviation and its noise's spread (deg); NaN or not given: not tested.
    range_phase_motion_deg : float
        What a single echo at ``settings.maximum_radial_speed_m_s`` shows in the range phase
        (deg; :func:`moving_echo_range_phase_deg`), added to its limit in quadrature.
    compensation_db : array_like, shape (n,)
        One-way beam compensation (dB, ≥ 0 in the main lobe).
    spacing : array_like, shape (n,)
        Range to the nearest other echo in the beam, in nominal pulse lengths.
    settings : processing.settings.SingleTargetSettings

    Returns
    -------
    ndarray of str, shape (n,)
    """
    st = settings
    ts = np.asarray(ts_comp_db, float)
    el = np.asarray(echo_length, float)
    pd = np.atleast_2d(np.asarray(phase_deviation_deg, float))
    pn = (np.full(pd.shape, np.nan) if phase_noise_deg is None
          else np.broadcast_to(np.atleast_2d(np.asarray(phase_noise_deg, float)), pd.shape))
    k = st.phase_deviation_sigmas
    # NaN compares False: a plane without a phase does not fail
    phase_bad = np.any(pd > phase_limit_deg(st.maximum_phase_deviation, pn, k), axis=0)
    rpd = (np.full(ts.shape, np.nan) if range_phase_deviation_deg is None
           else np.asarray(range_phase_deviation_deg, float))
    rpn = (np.full(ts.shape, np.nan) if range_phase_noise_deg is None
           else np.asarray(range_phase_noise_deg, float))
    range_bad = rpd > phase_limit_deg(st.maximum_range_phase_deviation, rpn, k, range_phase_motion_deg)
    comp = np.asarray(compensation_db, float)
    tests = {
        "sidelobe": np.asarray(sidelobe, bool),
        "image_edge": ~np.isfinite(el),
        "TS_threshold": ts < st.ts_threshold_db,
        "minimum_echo_duration": el < st.minimum_echo_duration,
        "maximum_echo_duration": el > st.maximum_echo_duration,
        "maximum_phase_deviation": phase_bad,
        "maximum_range_phase_deviation": range_bad,
        "gain_compensation": ~np.isfinite(ts) | ~(comp <= st.gain_compensation_db),
        "minimum_echo_spacing": np.asarray(spacing, float) < st.minimum_echo_spacing,
    }
    out = np.full(ts.shape, "", dtype=object)
    for rule in reversed(RULES):            # the earliest failing rule is written last
        out[tests[rule]] = rule
    return out.astype(str)
