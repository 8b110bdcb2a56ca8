"""Physical fish target strength: a gas-filled swimbladder, scattered by physical optics.

At 420 kHz a fish's echo is dominated by its swimbladder, a gas-filled, nearly pressure-release
body (R ≈ −1: the gas' impedance is 1/3500 of the water's; Foote 1980, J. Acoust. Soc. Am. 67,
2084; Clay & Horne 1994, J. Acoust. Soc. Am. 96, 1661). The bladder is modelled as a prolate
spheroid (length 2a along the fish, diameter 2b), meshed (an icosphere of ``subdivisions``
stretched to the semi-axes) and integrated by the physical-optics (Kirchhoff) facet integral of
:func:`acoustics.paths.scattering.po_backscatter` — the machinery of the mesh targets — with
R = −1 on the lit surface.

A fish at 15–25 m is in the far field of its bladder (L²/λ ≈ 3 m for 10 cm), so its echo is a
point scatterer whose complex amplitude f depends on one angle: the incidence angle α between the
direction from the transmitter and the bladder's broadside plane (α = 0: broadside; a spheroid of
revolution has no other dependence). f(α) is computed once per bladder and carrier on a grid of
``tilt_step`` over 0–90° (f(−α) = f(α)), cached in memory and on disk, and every fish of every
ping costs a table look-up. Between grid points the table interpolates f e^{−j2k h(α)}, f with the
phase of its specular point removed (h(α) = √(a² sin²α + b² cos²α), the distance from the centre
to the tangent plane facing the sonar): f itself turns by 2k dh/dα ≈ 1.5 rad per degree for a
10 cm bladder, the remainder slowly, so a coarse step suffices (docs/accuracy.md, *swimbladder*).

The fish's body axis comes from its heading (its swimming direction, or a uniform draw) and a tilt
drawn each ping from N(``tilt_mean_deg``, ``tilt_sd_deg``) (nose up positive), as Foote's
tilt-angle distributions average a fish's TS (Foote 1980, J. Acoust. Soc. Am. 67, 504).

Validity: within 0.5 dB of the exact prolate-spheroid modal series (PSMS, Furusawa 1988, as
implemented by ICES echoSMs) at 0.1–10° from broadside for kb = 8.8–17.6 (tests/test_fish_ts.py,
docs/accuracy.md); and of the geometric-optics limit σ_bs = a²b⁴ / (4 (a² sin²α + b² cos²α)²).
The echo's delay is the bladder centre's: the specular point is h (≈ b near broadside, about 1 cm)
nearer, a quarter of a range cell. The body's own echo (flesh, bones: ≈ 10 % of the total) and the
bladder's frequency dependence across the band (none in geometric optics) are left out.
"""
from __future__ import annotations

import numpy as np

__all__ = ["spheroid_triangles", "po_table", "specular_distance_m", "BladderTable",
           "swimbladder_table", "fish_amplitude", "body_axis"]


def spheroid_triangles(length_m: float, width_m: float, subdivisions: int) -> np.ndarray:
    """Facets of a prolate spheroid along x (semi-axes a = length/2, b = c = width/2).

    Returns
    -------
    ndarray, shape (20 x 4^subdivisions, 3, 3)
        Triangle vertices (m), counter-clockwise seen from outside.
    """
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=1.0)
    m.apply_scale([length_m / 2, width_m / 2, width_m / 2])
    return np.asarray(m.triangles, float)


def po_table(triangles, alpha_rad, wavenumber_rad_m: float, *, pressure_release: bool = True):
    """Physical-optics backscatter amplitude of a body for incidence at angles α from its
    broadside (+z) towards its long axis (+x), in the x–z plane.

    Parameters
    ----------
    triangles : ndarray, shape (n, 3, 3)
        Facets (m), outward normals.
    alpha_rad : array_like, shape (m,)
    wavenumber_rad_m : float

    Returns
    -------
    ndarray, shape (m,), complex
        f (m), phase referenced to the origin (p_s = f e^{−jkR}/R).
    """
    from acoustics.paths.scattering import po_backscatter
    alpha = np.atleast_1d(np.asarray(alpha_rad, float))
    out = np.empty(alpha.size, complex)
    for i, a in enumerate(alpha):
        # the incident wave travels towards the body: k̂ = −(sin α, 0, cos α) from a sonar on +z
        out[i] = po_backscatter(triangles, -np.array([np.sin(a), 0.0, np.cos(a)]),
                                wavenumber_rad_m, pressure_release=pressure_release)
    return out


def specular_distance_m(alpha_rad, length_m: float, width_m: float):
    """h(α) (m): distance from a prolate spheroid's centre to its tangent plane facing a sonar
    at angle α from broadside, √(a² sin²α + b² cos²α); shape of ``alpha_rad``."""
    a, b = length_m / 2, width_m / 2
    s = np.sin(alpha_rad)
    return np.sqrt(a * a * s * s + b * b * (1.0 - s * s))


def _grid(step_rad: float) -> np.ndarray:
    """|α| grid (rad) from 0 to 90° of step ``step_rad`` (the last step may be shorter)."""
    return np.unique(np.append(np.arange(0.0, np.pi / 2, step_rad), np.pi / 2))


class BladderTable:
    """f(α) of one bladder at one wavenumber, interpolated (see module docstring).

    Parameters
    ----------
    alpha_rad : ndarray, shape (m,)
        Grid of |α| from 0 to π/2 (rad), increasing.
    f_m : ndarray, shape (m,), complex
        f (m) at the grid, phase referenced to the bladder's centre.
    length_m, width_m, wavenumber_rad_m : float
    """

    def __init__(self, alpha_rad, f_m, *, length_m: float, width_m: float, wavenumber_rad_m: float):
        self.alpha_rad = np.asarray(alpha_rad, float)
        self.f_m = np.asarray(f_m, complex)
        self.length_m, self.width_m, self.k = float(length_m), float(width_m), float(wavenumber_rad_m)
        g = self.f_m * np.exp(-2j * self.k * specular_distance_m(self.alpha_rad, length_m, width_m))
        self._log_mag = np.log(np.maximum(np.abs(g), 1e-300))
        self._phase = np.unwrap(np.angle(g))

    def __call__(self, alpha_rad) -> np.ndarray:
        """f (m), complex, at incidence angles α (rad, any sign; |α| ≤ π/2), shape of
        ``alpha_rad``."""
        a = np.abs(np.asarray(alpha_rad, float))
        mag = np.exp(np.interp(a, self.alpha_rad, self._log_mag))
        phase = np.interp(a, self.alpha_rad, self._phase)
        h = specular_distance_m(a, self.length_m, self.width_m)
        return mag * np.exp(1j * (phase + 2 * self.k * h))


def swimbladder_table(spec, wavenumber_rad_m: float) -> BladderTable:
    """The f(α) table of a :class:`~acoustics.scene.targets_spec.SwimbladderTS` at k, computed
    once per (bladder, mesh, step, k) and cached in memory and on disk
    (:func:`acoustics.sonar.cache.per_geometry`: once per machine)."""
    from acoustics.sonar.cache import per_geometry
    key = (float(spec.length_m), float(spec.width_m), int(spec.subdivisions), float(spec.tilt_step),
           float(wavenumber_rad_m))

    def compute():
        alpha = _grid(spec.tilt_step)
        f = po_table(spheroid_triangles(spec.length_m, spec.width_m, spec.subdivisions), alpha,
                     wavenumber_rad_m)
        return alpha, f.real, f.imag

    alpha, re, im = per_geometry("swimbladder_table", key, compute)
    return BladderTable(alpha, re + 1j * im, length_m=spec.length_m, width_m=spec.width_m,
                        wavenumber_rad_m=wavenumber_rad_m)


def body_axis(heading_rad, tilt_rad) -> np.ndarray:
    """Unit vectors along the fish, nose forward (world frame, z down), shape (n, 3): heading in
    the horizontal plane from +x (north) towards +y (east), tilt nose up positive."""
    h, t = np.asarray(heading_rad, float), np.asarray(tilt_rad, float)
    return np.stack([np.cos(t) * np.cos(h), np.cos(t) * np.sin(h), -np.sin(t)], -1)


def fish_amplitude(spec, positions_world_m, transmitter_world_m, heading_rad, tilt_rad,
                   wavenumber_rad_m: float):
    """Complex backscatter amplitude of each fish and its incidence angle.

    Parameters
    ----------
    spec : SwimbladderTS
    positions_world_m : ndarray, shape (n, 3)
        Bladder centres (m).
    transmitter_world_m : array_like, shape (3,)
    heading_rad, tilt_rad : ndarray, shape (n,)
    wavenumber_rad_m : float

    Returns
    -------
    f : ndarray, shape (n,), complex
        Backscatter amplitude (m): σ_bs = |f|², phase referenced to the bladder's centre.
    alpha : ndarray, shape (n,)
        Incidence angle from broadside (rad), positive when the sonar is ahead of the fish's
        broadside plane. A fish at the transmitter (zero distance) reads α = 0.
    """
    p = np.asarray(positions_world_m, float).reshape(-1, 3)
    d = p - np.asarray(transmitter_world_m, float)
    dist = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.divide(d, dist, out=np.zeros_like(d), where=dist > 0)
    axis = body_axis(heading_rad, tilt_rad).reshape(-1, 3)
    # the direction from the fish to the sonar is −d: its component along the nose is sin α
    alpha = np.arcsin(np.clip(-np.sum(d * axis, axis=1), -1.0, 1.0))
    return swimbladder_table(spec, wavenumber_rad_m)(alpha), alpha
