"""The soft edge of the counting volume: each detection counts with the probability that its
fish lies inside, given its located elevation and that elevation's error.

The hard count (``count.volume_edge: hard``, the reference and the thesis' counting) counts a
detection when its located 3-D position lies inside the counting volume. The fan is thin
(±0.43° in elevation for ABACUS) and the interferometric elevation φ̂ has an error, so a fish just
beside the fan is sometimes placed inside and one just inside is sometimes placed outside. The
soft count (``count.volume_edge: soft``) counts each detection with

    w = P(|φ| ≤ φ_h | φ̂) = Φ((φ_h − φ̂)/σ) − Φ((−φ_h − φ̂)/σ)

(Φ the standard normal distribution function), the posterior probability that the fish is
inside for a Gaussian elevation error of standard deviation σ and a flat prior on φ across the
face: the per-ping count becomes the expected number of fish inside given the measurements.

What it buys, for fish spread uniformly across a face (σ small against the fan's width). Per
unit of face length in units of σ, with x = (φ − φ_h)/σ:

* both counts are unbiased: the hard count's mean is the number inside (a symmetric error
  moves as many in as out), and so is the soft one's (the posterior mean);
* the soft weight is the posterior mean of the indicator "inside", so it has the least mean
  *squared* error: ∫ Φ(t)(1 − Φ(t)) dt = 1/√π against the hard count's 2 ∫₀^∞ Φ(−x) dx =
  2/√(2π), a factor 1/√2. Summed over many fish (a run's total, a dense ping) the count's error
  variance falls by that factor;
* but its mean *absolute* error per fish is larger: E|w − 1_inside| = ∫ 2Φ(t)(1 − Φ(t)) dt =
  2/√π against 2/√(2π), a factor √2 — the hard decision is the posterior median, the best
  estimate under absolute error. Where a ping holds about one fish near the face, the per-ping
  nMAE (a sum of absolute errors) therefore gets worse, not better;

``tests/test_count_edge.py`` checks these against synthetic fish; docs/validation.md ("Counting
against density") reports what it does on the density benchmark.

σ is the Cramér–Rao bound of the interferometric elevation (docs/validation.md, "Interferometric
elevation precision against the Cramér–Rao bound": the chain's σ is within 1.06–1.18× of it on
an isolated target): var(Δψ) = 1/(2 SNR_A) + 1/(2 SNR_B) with SNR the image SNR per subarray,
taken equal for A and B, and σ_φ = σ_Δψ λ / (2π |b_y cos φ − (b_x sin θ + b_z cos θ) sin φ|).
The detections' ``snr_db`` is amplitude over the Rayleigh σ of one quadrature, 3.01 dB above the
image SNR, so var(Δψ) = 2 / 10^(snr_db/10). Optionally the SNR is capped by a
signal-to-interference ratio (``count.edge_interference_db``): in a school a strong echo's
elevation is limited by its neighbours' echoes, not by the noise. Only the elevation is soft:
range and azimuth errors (σ = δ/√(2 SNR), millimetres and hundredths of a degree) are small
against the volume's range and azimuth extent, where the elevation's face is 0.43° wide.
"""
from __future__ import annotations

import numpy as np

__all__ = ["elevation_sd_rad", "baseline_of", "soft_weights"]


def elevation_sd_rad(snr_db, azimuth_rad, elevation_rad, *, baseline_m, wavelength_m: float,
                     interference_db: float | None = None):
    """Standard deviation of the interferometric elevation of detections (rad): the Cramér–Rao
    bound for their SNR and direction.

    Parameters
    ----------
    snr_db : array_like, shape (n,)
        The detections' ``snr_db`` (amplitude over the Rayleigh σ of one quadrature, dB). NaN
        (no noise estimate) gives NaN.
    azimuth_rad, elevation_rad : array_like, shape (n,)
        Located direction θ, φ (rad).
    baseline_m : array_like, shape (3,)
        b = c_B − c_A (m), sonar frame.
    wavelength_m : float
    interference_db : float or None
        Signal-to-interference ratio (dB) that caps the image SNR; None: noise only.

    Returns
    -------
    ndarray, shape (n,)
        σ_φ (rad); inf where the baseline has no component that elevation changes (endfire).
    """
    b = np.asarray(baseline_m, float).reshape(3)
    th = np.asarray(azimuth_rad, float)
    ph = np.asarray(elevation_rad, float)
    snr_image = 10.0 ** (np.asarray(snr_db, float) / 10.0) / 2.0
    inv = 1.0 / snr_image
    if interference_db is not None:
        inv = inv + 10.0 ** (-float(interference_db) / 10.0)
    sd_psi = np.sqrt(inv)
    slope = 2 * np.pi / float(wavelength_m) * np.abs(
        b[1] * np.cos(ph) - (b[0] * np.sin(th) + b[2] * np.cos(th)) * np.sin(ph))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(slope > 0, sd_psi / np.where(slope > 0, slope, 1.0), np.inf)


def baseline_of(record):
    """The interferometric baseline of a record: b = c_B − c_A, the mean element positions of
    subarrays B and A.

    Parameters
    ----------
    record : processing.base.dataset.SonarRecord

    Returns
    -------
    ndarray, shape (3,), or None
        b (m, sonar frame); None without subarrays A and B.
    """
    groups = record.image_groups
    if "A" not in groups or "B" not in groups:
        return None
    pos = np.asarray(record.element_position_m, float)
    return pos[groups["B"]].mean(0) - pos[groups["A"]].mean(0)


def soft_weights(volume, positions_m, elevation_sd):
    """The probability that each detection's fish lies inside the counting volume.

    Parameters
    ----------
    volume : processing.base.counting_volume.CountingVolume
    positions_m : array_like, shape (n, 3)
        Located positions (m, sonar frame).
    elevation_sd : array_like, shape (n,)
        σ of each located elevation (rad); 0, NaN (unknown) or inf (no elevation information)
        counts that detection by the hard rule.

    Returns
    -------
    ndarray, shape (n,)
        w in [0, 1]: 0 outside the range and azimuth span; Φ((φ_h − φ̂)/σ) − Φ((−φ_h − φ̂)/σ)
        inside it; exactly ``volume.contains`` where σ is 0, NaN or inf.
    """
    from scipy.special import ndtr
    p = np.asarray(positions_m, float).reshape(-1, 3)
    sd = np.asarray(elevation_sd, float).reshape(-1)
    hard = volume.contains(p).astype(float)
    if not p.shape[0]:
        return hard
    r = np.linalg.norm(p, axis=1)
    az = np.arctan2(p[:, 0], p[:, 2])
    el = np.arctan2(p[:, 1], np.hypot(p[:, 0], p[:, 2]))
    edge = float(volume.elevation_halfwidth_rad)
    known = np.isfinite(sd) & (sd > 0)
    s = np.where(known, sd, 1.0)
    # Φ(a) − Φ(b) for b < a loses every digit where both are near 1: use the upper tails there
    hi, lo = (edge - el) / s, (-edge - el) / s
    prob = np.where(lo > 0, ndtr(-lo) - ndtr(-hi), ndtr(hi) - ndtr(lo))
    prob = np.clip(prob, 0.0, 1.0)
    return np.where(known, volume.in_span(r, az) * prob, hard)
