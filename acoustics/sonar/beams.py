"""Beam-pattern tools: principal cuts, beamwidths at a level, peak sidelobes.

The azimuth cut is the pattern over θ at φ = 0, the elevation cut over φ at θ = 0
(thesis §3.3). A beamwidth is the full angular width between the two points where the
pattern of the main lobe first falls to ``level_db`` below its peak, refined by root
finding on the continuous pattern (not read off a grid).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acoustics.sonar.arrays import ElementArray
from acoustics.sonar.directivity import array_pattern
from acoustics.medium import Medium
from acoustics.sonar import preset

__all__ = ["PLANES", "pattern_cut", "beamwidth", "peak_sidelobe_db", "BeamSummary",
           "summarize_beam"]

PLANES = ("azimuth", "elevation")
#: the ABACUS carrier (Table 3.1); used when no frequency is given
DEFAULT_FREQUENCY_HZ = preset.CENTER_FREQUENCY_HZ
_GRID = 36_001  # 0.005° spacing over ±90°: finer than any lobe of these arrays


def _k(medium: Medium | None, frequency_hz: float | None) -> float:
    medium = medium or Medium()
    return medium.wavenumber_rad_m(frequency_hz or DEFAULT_FREQUENCY_HZ)


def pattern_cut(array: ElementArray, *, plane: str, angles_rad=None, medium: Medium | None = None,
                frequency_hz: float | None = None, fidelity: str = "far_field",
                distance_m: float | None = None, subdivisions=(4, 4)):
    """Magnitude of a principal cut of an array's pattern.

    Parameters
    ----------
    array : ElementArray
    plane : {"azimuth", "elevation"}
    angles_rad : array_like, shape (A,), optional
        Angles (rad) of the cut; default 36 001 points over [-90°, 90°].
    medium : Medium, optional
        Sound speed (default 1530 m/s).
    frequency_hz : float, optional
        Default the ABACUS carrier 420.375 kHz.
    fidelity, distance_m, subdivisions
        As in :func:`acoustics.directivity.array_pattern`.

    Returns
    -------
    angles_rad : ndarray, shape (A,)
    magnitude : ndarray, shape (A,)
        |E| (dimensionless; 1 on axis in the far field for a ganged in-phase array).
    """
    if plane not in PLANES:
        raise ValueError(f"plane must be one of {PLANES}, got {plane!r}")
    if angles_rad is None:
        angles_rad = np.linspace(-np.pi / 2, np.pi / 2, _GRID)
    a = np.asarray(angles_rad, float)
    th, ph = (a, np.zeros_like(a)) if plane == "azimuth" else (np.zeros_like(a), a)
    e = array_pattern(array, th, ph, wavenumber_rad_m=_k(medium, frequency_hz), fidelity=fidelity,
                      distance_m=distance_m, subdivisions=subdivisions)
    return a, np.abs(e)


def _cut_fn(array, plane, k, fidelity, distance_m, subdivisions):
    def f(a):
        a = np.atleast_1d(np.asarray(a, float))
        th, ph = (a, np.zeros_like(a)) if plane == "azimuth" else (np.zeros_like(a), a)
        return np.abs(array_pattern(array, th, ph, wavenumber_rad_m=k, fidelity=fidelity,
                                    distance_m=distance_m, subdivisions=subdivisions))
    return f


def _main_lobe(a, mag):
    """Index of the main-lobe peak and of the minima bounding it on the grid."""
    i = int(np.argmax(mag))
    lo = i
    while lo > 0 and mag[lo - 1] <= mag[lo]:
        lo -= 1
    hi = i
    while hi < len(mag) - 1 and mag[hi + 1] <= mag[hi]:
        hi += 1
    return i, lo, hi


@dataclass(frozen=True)
class _Lobe:
    peak_angle: float
    peak: float
    left: float
    right: float


def _measure(array, *, plane, level_db, medium, frequency_hz, fidelity, distance_m, subdivisions):
    if not level_db < 0:
        raise ValueError(f"level_db must be negative (a level below the peak), got {level_db!r}")
    k = _k(medium, frequency_hz)
    f = _cut_fn(array, plane, k, fidelity, distance_m, subdivisions)
    a, mag = pattern_cut(array, plane=plane, medium=medium, frequency_hz=frequency_hz,
                         fidelity=fidelity, distance_m=distance_m, subdivisions=subdivisions)
    i, lo, hi = _main_lobe(a, mag)
    # refine the peak on the continuous pattern
    if 0 < i < len(a) - 1:
        from scipy.optimize import minimize_scalar  # here: a 0.3 s import, cached results
        res = minimize_scalar(lambda x: -f(x)[0], bounds=(a[i - 1], a[i + 1]), method="bounded",
                              options={"xatol": 1e-10})
        peak_angle, peak = float(res.x), float(-res.fun)
    else:
        peak_angle, peak = float(a[i]), float(mag[i])
    if peak <= 0:
        raise ValueError(f"{array.name}: the {plane} pattern is zero everywhere")
    target = peak * 10.0 ** (level_db / 20.0)
    g = lambda x: f(x)[0] - target  # noqa: E731
    edges = []
    for direction in (-1, 1):
        j = i
        while 0 <= j + direction < len(a) and mag[j + direction] > target:
            j += direction
        if not 0 <= j + direction < len(a):
            raise ValueError(f"{array.name}: the {plane} pattern never falls {-level_db:g} dB "
                             f"below its peak within ±90°")
        x0, x1 = sorted((a[j], a[j + direction]))
        from scipy.optimize import brentq
        edges.append(brentq(g, x0, x1, xtol=1e-12) if g(x0) * g(x1) < 0 else a[j + direction])
    return _Lobe(peak_angle, peak, edges[0], edges[1]), (a, mag, lo, hi)


def beamwidth(array: ElementArray, *, plane: str, level_db: float = -3.0,
              medium: Medium | None = None, frequency_hz: float | None = None,
              fidelity: str = "far_field", distance_m: float | None = None,
              subdivisions=(4, 4)) -> float:
    """Full width (rad) of the main lobe at ``level_db`` below its peak.

    Parameters
    ----------
    array : ElementArray
    plane : {"azimuth", "elevation"}
        Principal cut (φ = 0 or θ = 0).
    level_db : float
        Level relative to the peak, e.g. -3.0 or -10.0 (dB, one-way pattern).
    medium : Medium, optional
        Sound speed (default 1530 m/s).
    frequency_hz : float, optional
        Default 420.375 kHz.
    fidelity, distance_m, subdivisions
        As in :func:`acoustics.directivity.array_pattern`; default far field.

    Returns
    -------
    float
        Beamwidth in radians.

    Raises
    ------
    ValueError
        If the pattern never falls to the level within ±90°.
    """
    lobe, _ = _measure(array, plane=plane, level_db=level_db, medium=medium,
                       frequency_hz=frequency_hz, fidelity=fidelity, distance_m=distance_m,
                       subdivisions=subdivisions)
    return float(lobe.right - lobe.left)


def illuminated_extent(array: ElementArray, *, plane: str, level_db: float,
                       medium: Medium | None = None, frequency_hz: float | None = None) -> tuple:
    """Outermost angles at which a principal cut reaches ``level_db`` below its peak.

    Unlike :func:`beamwidth` this counts every lobe, sidelobes and grating lobes included: it is
    the angular extent a ray fan must cover to catch everything the array puts above the level.

    Parameters
    ----------
    array : ElementArray
    plane : {"azimuth", "elevation"}
    level_db : float
        Negative level (dB, one-way pattern) relative to the peak of the cut.
    medium : Medium, optional
    frequency_hz : float, optional

    Returns
    -------
    (lo_rad, hi_rad) : tuple of float
        On a 0.005° grid over [−90°, 90°]; the lobe edges are widened by one grid step.
    """
    if not level_db < 0:
        raise ValueError(f"level_db must be negative (a level below the peak), got {level_db!r}")
    a, mag = pattern_cut(array, plane=plane, medium=medium, frequency_hz=frequency_hz)
    above = np.flatnonzero(mag >= mag.max() * 10.0 ** (level_db / 20.0))
    step = a[1] - a[0]
    return (max(float(a[above[0]] - step), -np.pi / 2), min(float(a[above[-1]] + step), np.pi / 2))


def peak_sidelobe_db(array: ElementArray, *, plane: str, medium: Medium | None = None,
                     frequency_hz: float | None = None, fidelity: str = "far_field",
                     distance_m: float | None = None, subdivisions=(4, 4)) -> float:
    """Highest lobe outside the main lobe, in dB relative to the main-lobe peak.

    Grating lobes count as sidelobes. Returns ``-inf`` when the cut has no other lobe
    within ±90° (documented; JSON output writes it as null).
    """
    lobe, (a, mag, lo, hi) = _measure(array, plane=plane, level_db=-3.0, medium=medium,
                                      frequency_hz=frequency_hz, fidelity=fidelity,
                                      distance_m=distance_m, subdivisions=subdivisions)
    outside = np.concatenate([mag[:lo], mag[hi + 1:]])
    if outside.size == 0 or outside.max() <= 0:
        return float("-inf")
    return float(20.0 * np.log10(outside.max() / lobe.peak))


@dataclass(frozen=True)
class BeamSummary:
    """Beamwidths (deg) and peak sidelobes (dB) of one array in both principal planes."""

    azimuth_3db_deg: float
    elevation_3db_deg: float
    azimuth_10db_deg: float
    elevation_10db_deg: float
    azimuth_peak_sidelobe_db: float
    elevation_peak_sidelobe_db: float

    @property
    def peak_sidelobe_db(self) -> float:
        return max(self.azimuth_peak_sidelobe_db, self.elevation_peak_sidelobe_db)

    def as_dict(self) -> dict:
        def clean(x):
            return None if not np.isfinite(x) else round(float(x), 4)
        return {"azimuth_3db_deg": clean(self.azimuth_3db_deg),
                "elevation_3db_deg": clean(self.elevation_3db_deg),
                "azimuth_10db_deg": clean(self.azimuth_10db_deg),
                "elevation_10db_deg": clean(self.elevation_10db_deg),
                "peak_sidelobe_db": clean(self.peak_sidelobe_db),
                "azimuth_peak_sidelobe_db": clean(self.azimuth_peak_sidelobe_db),
                "elevation_peak_sidelobe_db": clean(self.elevation_peak_sidelobe_db)}


def summarize_beam(array: ElementArray, *, medium: Medium | None = None,
                   frequency_hz: float | None = None, fidelity: str = "far_field",
                   distance_m: float | None = None) -> BeamSummary:
    """3 dB and 10 dB widths and peak sidelobes of ``array`` in both planes."""
    kw = dict(medium=medium, frequency_hz=frequency_hz, fidelity=fidelity, distance_m=distance_m)
    vals = {}
    for plane in PLANES:
        for lvl in (3, 10):
            vals[f"{plane}_{lvl}db_deg"] = np.degrees(beamwidth(array, plane=plane, level_db=-lvl, **kw))
        vals[f"{plane}_peak_sidelobe_db"] = peak_sidelobe_db(array, plane=plane, **kw)
    return BeamSummary(**vals)
