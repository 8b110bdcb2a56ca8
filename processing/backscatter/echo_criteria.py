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

__all__ = ["RULES", "nominal_echo_length_m", "echo_shape", "echo_spacing", "verdicts"]

#: the rules, in the order they are tested; a rejected candidate names the first it fails
RULES = ("sidelobe", "image_edge", "TS_threshold", "minimum_echo_duration", "maximum_echo_duration",
         "maximum_phase_deviation", "gain_compensation", "minimum_echo_spacing")


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
    spec = np.asarray(response, float)
    n = spec.size
    big = np.zeros(n * upsample)
    h = n // 2
    big[:h], big[n * upsample - (n - h):] = spec[:h], spec[h:]
    env = np.fft.fftshift(np.abs(np.fft.ifft(big)))
    lo, hi = _crossings(env, int(np.argmax(env)), 10.0 ** (-level_db / 20.0))
    return float((hi - lo) / (rate_hz * upsample) * sound_speed_m_s / 2.0)


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


def echo_shape(envelope, row: int, *, range_step_m: float, level_db: float = 6.0, cross=None,
               neighbours=None, search_rows: int = 2):
    """Echo length and phase deviation of one echo in one beam.

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

    Returns
    -------
    length_m : float
        Echo length (m); NaN when the echo runs off the image (its end is not seen).
    phase_deviation_deg : float
        Standard deviation of ψ_AB over the samples within the ends (deg); NaN without ``cross``
        or when the echo runs off the image.
    beam_offset_sd : float
        Standard deviation of the beam-domain peak over the same samples (in beam steps); NaN
        without ``neighbours``.
    """
    env = np.asarray(envelope, float)
    n = env.size
    a, b = max(0, row - search_rows), min(n, row + search_rows + 1)
    peak = a + int(np.argmax(env[a:b]))
    if not env[peak] > 0:
        return np.nan, np.nan, np.nan
    lo, hi = _crossings(env, peak, 10.0 ** (-level_db / 20.0))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return np.nan, np.nan, np.nan
    length = float((hi - lo) * range_step_m)
    rows = np.arange(int(np.ceil(lo)), int(np.floor(hi)) + 1)
    phase_sd = offset_sd = np.nan
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
    return length, phase_sd, offset_sd


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
             spacing, settings):
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
    phase_deviation_deg : array_like, shape (n,)
        NaN: no phase (not interferometric), the rule is skipped.
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
    pd = np.asarray(phase_deviation_deg, float)
    comp = np.asarray(compensation_db, float)
    tests = {
        "sidelobe": np.asarray(sidelobe, bool),
        "image_edge": ~np.isfinite(el),
        "TS_threshold": ts < st.ts_threshold_db,
        "minimum_echo_duration": el < st.minimum_echo_duration,
        "maximum_echo_duration": el > st.maximum_echo_duration,
        "maximum_phase_deviation": (np.zeros(pd.shape, bool) if st.maximum_phase_deviation is None
                                    else pd > st.maximum_phase_deviation),
        "gain_compensation": ~np.isfinite(ts) | ~(comp <= st.gain_compensation_db),
        "minimum_echo_spacing": np.asarray(spacing, float) < st.minimum_echo_spacing,
    }
    out = np.full(ts.shape, "", dtype=object)
    for rule in reversed(RULES):            # the earliest failing rule is written last
        out[tests[rule]] = rule
    return out.astype(str)
