"""Scattering models for boundaries and mesh targets.

``lambert_sb``
    Lambert's law for diffuse boundary backscatter, s_b = μ sin² θ_g per unit area (Lurton,
    *An Introduction to Underwater Acoustics*, 2010, §3.4).
``rayleigh_reflection``
    plane-wave reflection coefficient of a fluid half-space (Rayleigh; Brekhovskikh & Lysanov,
    *Fundamentals of Ocean Acoustics*, §4.2): complex beyond the critical angle.
``triangle_phase_integral``
    ∫_T e^{j q·(x − c)} dS over a flat triangle in closed form (Gordon 1975, "Far-field
    approximations to the Kirchhoff–Helmholtz representations of scattered fields", IEEE Trans.
    Antennas Propag. 23(4)), evaluated through the second divided difference of e^{jx}
    (Hermite–Genocchi), with series where its points coincide — stable at normal incidence.
``po_backscatter``
    monostatic physical-optics (Kirchhoff) backscatter amplitude of a faceted body,
    f = (jk/2π) Σ_lit (−n̂·k̂) ∫_facet e^{−2jk k̂·x} dS (|f| = A/λ for a plate at normal incidence;
    |f| → a/2 for a sphere), with the convention p_s = f e^{−jkR}/R of docs/conventions.md.
``rigid_sphere_backscatter``
    the exact modal series of a rigid sphere (Anderson 1950; Medwin & Clay, *Fundamentals of
    Acoustical Oceanography*, 1998, §7.4), the reference for mesh targets.
"""
from __future__ import annotations

import numpy as np
from scipy.special import spherical_jn, spherical_yn

__all__ = ["lambert_sb", "rayleigh_reflection", "triangle_phase_integral", "po_backscatter",
           "rigid_sphere_backscatter"]


def lambert_sb(grazing_rad, mu_db: float):
    """Backscattering cross-section per unit area s_b (m²/m², dimensionless) at grazing angle θ_g."""
    return 10.0 ** (mu_db / 10.0) * np.sin(np.asarray(grazing_rad, float)) ** 2


def rayleigh_reflection(incidence_rad, *, density_ratio: float, speed_ratio: float):
    """Plane-wave reflection coefficient of a fluid half-space.

    Parameters
    ----------
    incidence_rad : array_like
        Angle from the normal (rad), 0 = normal incidence.
    density_ratio : float
        m = ρ2/ρ1 (bottom / water).
    speed_ratio : float
        c2/c1 (bottom / water); n = c1/c2.

    Returns
    -------
    ndarray, complex
        R = (m cos θ − s) / (m cos θ + s), s = k_2z / k_1 = √(n² − sin² θ); |R| = 1 beyond
        critical.

    Notes
    -----
    Beyond the critical angle s is imaginary, and the branch is physics, not convention: under
    the project's e^{+jωt} (docs/conventions.md) the transmitted wave e^{j(ωt − k_2z z)} must
    decay into the bottom (z > 0), so Im k_2z < 0 and s = −j √(sin² θ − n²). numpy's principal
    square root gives +j: the growing wave, and R's complex conjugate. Here the root with
    Im s ≤ 0 is taken, so arg R = 2 atan(√(sin² θ − n²) / (m cos θ)) ∈ (0, π) beyond critical.
    """
    th = np.asarray(incidence_rad, float)
    n = 1.0 / speed_ratio
    root = np.sqrt((n * n - np.sin(th) ** 2).astype(complex))
    root = np.where(root.imag > 0, np.conj(root), root)   # the decaying branch (Im ≤ 0)
    m = density_ratio
    return (m * np.cos(th) - root) / (m * np.cos(th) + root)


def _exp_dd2(a, b):
    """F(a, b) = ∫_0^1∫_0^{1−s} e^{j(a s + b t)} dt ds for arrays a, b.

    F is symmetric in (a, b); with |b| >= |a|, F = [e^{jb} E(a − b) − E(a)] / (jb),
    E(x) = (e^{jx} − 1)/(jx), which divides by the larger argument and so is exact whenever
    |b| >= 1e-3 (E handles a = b and a = 0). Both small: Taylor to third order, using
    ∫∫ s^i t^k = i! k! / (i + k + 2)!.
    """
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    swap = np.abs(a) > np.abs(b)
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    out = np.empty(a.shape, complex)
    small = np.abs(b) < 1e-3
    x, y = a[small], b[small]
    out[small] = (0.5 + 1j * (x + y) / 6 - (x * x + x * y + y * y) / 24
                  - 1j * (x**3 + x * x * y + x * y * y + y**3) / 120)
    x, y = a[~small], b[~small]
    out[~small] = (np.exp(1j * y) * _e1(x - y) - _e1(x)) / (1j * y)
    return out


def _e1(x):
    """(e^{jx} − 1)/(jx), 1 at x = 0."""
    x = np.asarray(x, float)
    small = np.abs(x) < 1e-6
    xs = np.where(small, 1.0, x)
    return np.where(small, 1 + 0.5j * x, (np.exp(1j * xs) - 1) / (1j * xs))


def triangle_phase_integral(vertices, q):
    """∫_T e^{j q·(x − c)} dS over triangles, c their centroids (closed form, Gordon 1975).

    Parameters
    ----------
    vertices : array_like, shape (n, 3, 3)
        Triangle vertices (m).
    q : array_like, shape (3,) or (n, 3)
        Phase gradient (rad/m).

    Returns
    -------
    ndarray, shape (n,), complex
        Exactly the area when q is normal to the triangle.
    """
    v = np.asarray(vertices, float)
    qv = np.broadcast_to(np.asarray(q, float), (v.shape[0], 3))
    c = v.mean(axis=1)
    e1 = v[:, 1] - v[:, 0]
    e2 = v[:, 2] - v[:, 0]
    area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    a = np.einsum("ij,ij->i", qv, e1)
    b = np.einsum("ij,ij->i", qv, e2)
    phase0 = np.exp(1j * np.einsum("ij,ij->i", qv, v[:, 0] - c))
    return area2 * phase0 * _exp_dd2(a, b)


def po_backscatter(triangles, k_hat, wavenumber, *, lit=None, pressure_release=False,
                   reference=None):
    """Monostatic physical-optics backscatter amplitude f (m) of a faceted body.

    Parameters
    ----------
    triangles : array_like, shape (n, 3, 3)
        Facets (m), counter-clockwise seen from outside (outward normals).
    k_hat : array_like, shape (3,)
        Unit direction of incidence (from the sonar towards the body).
    wavenumber : float or array_like (n_f,)
        k (rad/m); an array gives f at each.
    lit : array_like of bool, shape (n,), optional
        Facets that count (ensonified and visible); default those facing the sonar.
    reference : array_like, shape (3,), optional
        Phase reference point (m); default the origin.

    Returns
    -------
    complex or ndarray (n_f,)
        f with p_s = f e^{−jkR}/R; σ_bs = |f|², TS = 20 log10 |f|.
    """
    tri = np.asarray(triangles, float)
    kh = np.asarray(k_hat, float) / np.linalg.norm(k_hat)
    ref = np.zeros(3) if reference is None else np.asarray(reference, float)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    cosine = -(n @ kh)
    sel = cosine > 0 if lit is None else np.asarray(lit, bool)
    tri, cosine = tri[sel], cosine[sel]
    c = tri.mean(axis=1)
    ks = np.atleast_1d(np.asarray(wavenumber, float))
    out = np.empty(ks.size, complex)
    for i, k in enumerate(ks):
        integral = triangle_phase_integral(tri, -2 * k * kh)
        phase = np.exp(-2j * k * ((c - ref) @ kh))
        out[i] = 1j * k / (2 * np.pi) * np.sum(cosine * integral * phase)
    if pressure_release:
        out = -out
    return out[0] if np.ndim(wavenumber) == 0 else out


def rigid_sphere_backscatter(ka, radius_m):
    """Backscatter amplitude |f| (m) of a rigid sphere by the modal series.

    Parameters
    ----------
    ka : array_like
        k a.
    radius_m : float

    Returns
    -------
    ndarray
        |f| (m); σ_bs = |f|², → a/2 as ka → ∞.
    """
    ka = np.atleast_1d(np.asarray(ka, float))
    out = np.empty(ka.size)
    for i, x in enumerate(ka):
        nmax = int(x + 4.05 * x ** (1 / 3) + 10)
        n = np.arange(nmax + 1)
        jp = spherical_jn(n, x, derivative=True)
        yp = spherical_yn(n, x, derivative=True)
        coef = jp / (jp + 1j * yp)
        s = np.sum((2 * n + 1) * (-1.0) ** n * coef)
        out[i] = abs(s) / (x / radius_m)
    return out
