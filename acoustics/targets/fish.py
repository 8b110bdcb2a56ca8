"""Physical fish target strength: a gas-filled swimbladder, scattered by physical optics.

At 420 kHz a fish's echo is dominated by its swimbladder, a gas-filled, nearly pressure-release
body (Foote 1980, J. Acoust. Soc. Am. 67, 2084). The bladder is modelled as a prolate spheroid
(length 2a along the fish, diameter 2b), meshed and integrated by the physical-optics (Kirchhoff)
facet integral of :func:`acoustics.paths.scattering.po_backscatter` — the machinery of the mesh
targets, with R = −1 on the surface.

A fish at 15–25 m is in the far field of its bladder (L²/λ ≈ 3 m for 10 cm), so its echo is a
point scatterer whose complex amplitude f depends on one angle: the incidence angle α between the
direction from the transmitter and the bladder's broadside plane (α = 0: broadside). f(α) is
tabulated once per bladder and carrier (cached) on a grid of ``tilt_step`` and interpolated
(real and imaginary parts, linearly); every fish of every ping then costs a table look-up. The
fish's body axis comes from its heading (its swimming direction, or a uniform draw) and a tilt
drawn each ping from N(``tilt_mean_deg``, ``tilt_sd_deg``) (nose up positive).

Validity: checked against the exact prolate-spheroid modal series (PSMS, Furusawa 1988, as
implemented by ICES echoSMs) within 0.2 dB for |α| ≤ 10° when kb ≥ 8 (tests/test_fish_ts.py,
docs/accuracy.md "swimbladder"); physical optics loses accuracy far from broadside on thin
bladders (≈ 1 dB at 15° for kb = 4.4), where the echo is 15–20 dB below its peak.
"""
from __future__ import annotations

import numpy as np

__all__ = ["spheroid_triangles", "swimbladder_table", "fish_amplitude", "body_axis"]

_TABLES: dict = {}


def spheroid_triangles(length_m: float, width_m: float, subdivisions: int) -> np.ndarray:
    """Facets (m) of a prolate spheroid along x (semi-axes a = length/2, b = c = width/2),
    shape (n, 3, 3), outward normals."""
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=1.0)
    m.apply_scale([length_m / 2, width_m / 2, width_m / 2])
    return np.asarray(m.triangles, float)


#: beyond this angle from broadside the table steps 1°: the echo is 20 dB and more below its peak
_FINE_SPAN = np.radians(30.0)


def _table_angles(step_rad: float) -> np.ndarray:
    """|α| grid (rad): ``step`` within ±30° of broadside, 1° beyond, to 90°."""
    fine = np.arange(0.0, _FINE_SPAN, step_rad)
    coarse = np.arange(_FINE_SPAN, np.pi / 2 + 1e-12, np.radians(1.0))
    return np.unique(np.concatenate([fine, coarse, [np.pi / 2]]))


def swimbladder_table(spec, wavenumber_rad_m: float):
    """(α grid (rad), f (complex, m)) of a bladder for incidence at angle α from broadside,
    α in [−90°, 90°]: every ``spec.tilt_step`` within 30° of broadside, every 1° beyond (a
    spheroid is symmetric, f(−α) = f(α)). Cached per (bladder, k) in memory and on disk
    (:mod:`acoustics.sonar.cache`): computed once per machine."""
    from acoustics.sonar.cache import per_geometry
    key = (float(spec.length_m), float(spec.width_m), int(spec.subdivisions), float(spec.tilt_step),
           float(wavenumber_rad_m))
    if key not in _TABLES:
        half, f_half = per_geometry("swimbladder", key, lambda: _compute_table(spec, wavenumber_rad_m))
        alpha = np.concatenate([-half[:0:-1], half])
        f = np.concatenate([f_half[:0:-1], f_half])
        if len(_TABLES) > 16:
            _TABLES.clear()
        _TABLES[key] = (alpha, f)
    return _TABLES[key]


def _compute_table(spec, wavenumber_rad_m: float):
    from acoustics.paths.scattering import po_backscatter
    tri = spheroid_triangles(spec.length_m, spec.width_m, spec.subdivisions)
    alpha = _table_angles(spec.tilt_step)
    f = np.empty(alpha.size, complex)
    for i, a in enumerate(alpha):
        # incidence in the x–z plane, α from broadside (+z) towards the long axis (+x)
        f[i] = po_backscatter(tri, np.array([np.sin(a), 0.0, np.cos(a)]), wavenumber_rad_m,
                              pressure_release=True)
    return alpha, f


def body_axis(heading_rad, tilt_rad) -> np.ndarray:
    """Unit vectors along the fish (world frame, z down), shape (n, 3): heading in the horizontal
    plane from +x towards +y, tilt nose up positive."""
    h, t = np.asarray(heading_rad, float), np.asarray(tilt_rad, float)
    return np.stack([np.cos(t) * np.cos(h), np.cos(t) * np.sin(h), -np.sin(t)], -1)


def fish_amplitude(spec, positions_world_m, transmitter_world_m, heading_rad, tilt_rad,
                   wavenumber_rad_m: float):
    """Complex backscatter amplitude f (m) of each fish, shape (n,), and its incidence angle α
    (rad, from broadside), shape (n,).

    Parameters
    ----------
    spec : SwimbladderTS
    positions_world_m : ndarray, shape (n, 3)
    transmitter_world_m : array_like, shape (3,)
    heading_rad, tilt_rad : ndarray, shape (n,)
    wavenumber_rad_m : float
    """
    p = np.asarray(positions_world_m, float).reshape(-1, 3)
    d = p - np.asarray(transmitter_world_m, float)
    dist = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.divide(d, dist, out=np.zeros_like(d), where=dist > 0)
    axis = body_axis(heading_rad, tilt_rad)
    alpha = np.arcsin(np.clip(np.sum(d * axis, axis=1), -1.0, 1.0))
    grid, f = swimbladder_table(spec, wavenumber_rad_m)
    return np.interp(alpha, grid, f.real) + 1j * np.interp(alpha, grid, f.imag), alpha
