"""The coincidence correction of per-ping counts: fish lost because two share a resolution cell.

Echo counting counts echoes, not fish: two fish closer than the sonar resolves (range resolution
× azimuth resolution, the whole fan's thickness in elevation, which the image cannot resolve)
give one echo. With fish spread uniformly, the chance of that is the occupancy statistics of
counting — the "coincidence" (dead-time) correction of counting statistics, and the fisheries
acoustician's N_v index (Sawada et al. 1993: the mean number of fish per reverberation volume,
echo counting biased once it nears 0.1).

The model. A fish at range r hides, or is hidden by, any other fish whose echo falls within
``u`` resolution cells of its own in the image: the circle of radius u in (Δr / δr,
r Δsin θ / (r δθ)) — the matching rule's "shared cell" (:mod:`processing.detection.scoring`,
``count.unresolved_cells`` = 1.5, the Rayleigh limit of a Hamming-weighted aperture) — through
the counting volume's elevation extent. Its volume is

    v_x(r) = π u² · δr · r δθ · r · 2 sin φ_h,

and over the counting volume (r² averaged over r1..r2 for fish uniform in the sector)
a = ⟨v_x⟩ / (2 V). Points of a uniform (Poisson) field merge into clusters; as for a counter
with dead time, the number of clusters (echoes) of N fish is N·exp(−N ⟨v_x⟩ / (2 V)): each
merged pair costs one count, half a fish each. The correction inverts it for the detected
count D of one ping:

    D = N e^(−a N)   ⇒   N̂ = −W₀(−a D) / a     (Lambert's W, principal branch),

≈ D (1 + a D) at small aD. It assumes fish spread uniformly and independently through and
around the volume, echoes merged only by a neighbour inside the cell (no sidelobe or
threshold losses), and every merged cluster counted once. Where it stops holding:

* schools are not Poisson: pairs of fish swimming side by side stay unresolved for many
  pings and a minimum spacing forbids the closest pairs, so at low density the loss of one run
  is far from its mean (the correction is a mean, right over many pings and runs, not per ping:
  it adds a fraction of a fish to every ping, the pings with no loss too);
* at high density the loss has other causes than the cell (a neighbour's echo drags the
  located elevation out of the volume, a stronger fish's sidelobe rule, fish beside the fan
  merging with fish in it) that the model does not hold, so it corrects only part of it
  (docs/validation.md, "Counting against density");
* at a D ≥ 1 / (e a) the count saturates — more fish no longer give more echoes — and N̂ is
  capped at 1/a (the most fish the count can hold: a lower bound).

The setting ``count.coincidence_correction`` ("none", the reference and default; "poisson")
chooses it; with "poisson" /Processing/Counts gains ``count_corrected`` and the density is
its count over the volume.
"""
from __future__ import annotations

import numpy as np

__all__ = ["coincidence_coefficient", "corrected_count"]


def coincidence_coefficient(volume, *, range_resolution_m: float, azimuth_resolution_rad: float,
                            unresolved_cells: float = 1.5) -> float:
    """The loss coefficient a of D = N e^(−a N): half the mean exclusion volume of a fish over
    the counting volume.

    Parameters
    ----------
    volume : processing.base.counting_volume.CountingVolume
        Ranges r1..r2 (m), azimuth and elevation half-widths (rad), volume V (m³).
    range_resolution_m, azimuth_resolution_rad : float
        The image's 3 dB widths δr (m) and δθ (rad).
    unresolved_cells : float
        u: two echoes closer than this many cells are one.

    Returns
    -------
    float
        a (dimensionless: per fish in the volume); 0 for an empty volume.
    """
    r1, r2 = (float(x) for x in np.asarray(volume.range_m, float).ravel())
    v = float(volume.volume_m3)
    if not (v > 0 and r2 > r1):
        return 0.0
    # r² averaged over a sector uniform in volume (weight r²): 3/5 (r2⁵ − r1⁵)/(r2³ − r1³)
    mean_r2 = 0.6 * (r2 ** 5 - r1 ** 5) / (r2 ** 3 - r1 ** 3)
    excl = (np.pi * float(unresolved_cells) ** 2 * float(range_resolution_m) * float(azimuth_resolution_rad)
            * mean_r2 * 2.0 * np.sin(float(volume.elevation_halfwidth_rad)))
    return excl / (2.0 * v)


def corrected_count(count, coefficient: float):
    """The expected number of fish N̂ behind ``count`` echoes, inverting D = N e^(−a N).

    Parameters
    ----------
    count : array_like, shape (n,)
        Detected counts D per ping (NaN passes through: no interferometry, no count).
    coefficient : float
        a (:func:`coincidence_coefficient`).

    Returns
    -------
    ndarray, shape (n,)
        N̂ (float) = −W₀(−a D) / a; D where a = 0; capped at 1/a where a D ≥ 1/e (the count
        saturates there: N̂ is then a lower bound). NaN only where ``count`` is NaN.
    """
    from scipy.special import lambertw
    d = np.asarray(count, float)
    a = float(coefficient)
    if a <= 0:
        return d.copy()
    x = a * np.nan_to_num(d, nan=0.0)
    saturated = x >= 1.0 / np.e
    # W₀ at the branch point −1/e is −1 (scipy's lambertw returns NaN exactly there)
    n = np.where(saturated, 1.0 / a, -lambertw(-np.where(saturated, 0.0, x), 0).real / a)
    return np.where(np.isfinite(d), np.where(d > 0, n, 0.0), np.nan)
