"""Element-level Huygens directivity of rectangular pistons and arrays of them.

Thesis eq. 2.8–2.11: each element radiates the far-field pattern of a baffled rectangular
piston, sinc(k w/2 · u_x') sinc(k h/2 · u_y'), where u_x', u_y' are the direction cosines
of the field point in the element's own axes (the thesis writes sin θ', sin φ'; they agree
on the principal cuts and the direction cosines are the exact Fraunhofer result). The array
sums its elements with each element's exact path phase e^{-jkR_e}.

Two fidelity settings (the accuracy knob; docs/accuracy.md):

``far_field``
    the analytic element pattern from each element's centre (the thesis' model).
``huygens``
    each element split into n x m sub-pistons, each summed with its own exact distance
    and spreading. The sub-pistons carry their own (small) sinc patterns, and because
    sinc(Nx) = [sin(Nx) / (N sin x)] sinc(x) exactly, the sum tends to ``far_field`` as the
    field distance grows for every n, m; n, m control the near-field accuracy only.

Conventions: field e^{j(ωt - kR)}, so a path R carries e^{-jkR}; sonar-frame coordinates;
elements face +z and, with ``baffle=True`` (rigid baffle), do not radiate into z < 0.
"""
from __future__ import annotations

import numpy as np

from acoustics.sonar.arrays import ElementArray

__all__ = ["FIDELITIES", "unit_vector", "element_directivity", "array_response",
           "array_pattern"]

FIDELITIES = ("far_field", "huygens")
#: elements x sub-sources x points handled per block (bounds memory to ~100 MB)
_BLOCK = 2_000_000


def unit_vector(azimuth_rad, elevation_rad):
    """Direction (..., 3) of sonar-frame azimuth θ and elevation φ (thesis §2.1.1)."""
    th, ph = np.broadcast_arrays(np.asarray(azimuth_rad, float), np.asarray(elevation_rad, float))
    cph = np.cos(ph)
    return np.stack([cph * np.sin(th), np.sin(ph), cph * np.cos(th)], -1)


def _piston(ux, uy, uz, half_kw, half_kh, baffle):
    """sinc·sinc of direction cosines; np.sinc is exact (1) at 0, so broadside is safe."""
    d = np.sinc(half_kw * ux / np.pi) * np.sinc(half_kh * uy / np.pi)
    if baffle:
        d = np.where(uz < 0.0, 0.0, d)
    return d


def _path_difference(points, centers, reference):
    """|P - c| - |P - ref| computed without cancellation, shapes (P,1,3),(1,n,3),(3,)."""
    dc = points - centers
    dr = points - reference
    rc = np.sqrt(np.einsum("...k,...k->...", dc, dc))
    rr = np.sqrt(np.einsum("...k,...k->...", dr, dr))
    # |a|^2 - |b|^2 = (b - a)·(a + b) with a = P - c, b = P - ref
    num = np.einsum("...k,...k->...", (reference - centers), (dc + dr))
    den = rc + rr
    diff = np.divide(num, den, out=np.zeros(np.broadcast_shapes(num.shape, den.shape)),
                     where=den > 0)
    return diff, rc, rr


def _check_fidelity(fidelity, subdivisions):
    if fidelity not in FIDELITIES:
        raise ValueError(f"fidelity must be one of {FIDELITIES}, got {fidelity!r}")
    n, m = (int(s) for s in subdivisions)
    if n < 1 or m < 1:
        raise ValueError(f"subdivisions must be positive integers, got {subdivisions!r}")
    return n, m


def element_directivity(elements: ElementArray, points_m, *, wavenumber_rad_m: float,
                        fidelity: str = "far_field", subdivisions=(4, 4),
                        baffle: bool = True):
    """Directivity of every element towards every field point.

    Parameters
    ----------
    elements : ElementArray
        n elements.
    points_m : array_like, shape (P, 3)
        Field points (m) in the sonar frame.
    wavenumber_rad_m : float
        k = 2π f / c (rad/m).
    fidelity : {"far_field", "huygens"}
        See the module docstring.
    subdivisions : (int, int)
        Sub-pistons per element along its local x and y (``huygens`` only).
    baffle : bool
        No radiation behind the element plane.

    Returns
    -------
    ndarray, shape (P, n)
        ``far_field``: real float64, sinc·sinc, 1 on the element's axis and |D| <= 1.
        ``huygens``: complex128, normalised so that it tends to the ``far_field`` value as
        the distance grows; its phase is relative to the path from the element's centre
        (the centre path itself is left to the caller, who needs it for delays).
        A point on an element's centre gets the on-axis value, never NaN.
    """
    n_sub, m_sub = _check_fidelity(fidelity, subdivisions)
    pts = np.asarray(points_m, float).reshape(-1, 3)
    ex, ey = elements.local_axes
    c = elements.center_m
    k = float(wavenumber_rad_m)
    n_el = elements.n_elements
    if fidelity == "far_field":
        out = np.empty((pts.shape[0], n_el))
        step = max(1, _BLOCK // max(n_el, 1))
        for s in range(0, pts.shape[0], step):
            d = pts[s:s + step, None, :] - c[None]
            r = np.sqrt(np.einsum("pnk,pnk->pn", d, d))
            u = d / np.where(r > 0, r, 1.0)[..., None]
            u[r == 0] = (0.0, 0.0, 1.0)
            ux = np.einsum("pnk,nk->pn", u, ex)
            uy = np.einsum("pnk,nk->pn", u, ey)
            out[s:s + step] = _piston(ux, uy, u[..., 2], 0.5 * k * elements.width_m,
                                      0.5 * k * elements.height_m, baffle)
        return out
    # huygens: sub-piston centres, offsets in each element's local axes
    fx = (np.arange(n_sub) + 0.5) / n_sub - 0.5
    fy = (np.arange(m_sub) + 0.5) / m_sub - 0.5
    gx, gy = np.meshgrid(fx, fy, indexing="ij")
    gx, gy = gx.ravel(), gy.ravel()  # (S,)
    off = (gx[None, :, None] * elements.width_m[:, None, None] * ex[:, None, :]
           + gy[None, :, None] * elements.height_m[:, None, None] * ey[:, None, :])  # (n,S,3)
    sub_c = c[:, None, :] + off
    half_kw = 0.5 * k * elements.width_m / n_sub
    half_kh = 0.5 * k * elements.height_m / m_sub
    out = np.empty((pts.shape[0], n_el), complex)
    n_s = gx.size
    step = max(1, _BLOCK // max(n_el * n_s, 1))
    for s in range(0, pts.shape[0], step):
        p = pts[s:s + step, None, None, :]
        d = p - sub_c[None]                                   # (p,n,S,3)
        r = np.sqrt(np.einsum("pnsk,pnsk->pns", d, d))
        u = d / np.where(r > 0, r, 1.0)[..., None]
        u[r == 0] = (0.0, 0.0, 1.0)
        ux = np.einsum("pnsk,nk->pns", u, ex)
        uy = np.einsum("pnsk,nk->pns", u, ey)
        dsub = _piston(ux, uy, u[..., 2], half_kw[:, None], half_kh[:, None], baffle)
        # exact path of each sub-piston relative to the element centre's path
        diff, r_sub, r_c = _path_difference(p, sub_c[None], c[None, :, None, :])
        spread = np.divide(r_c, r_sub, out=np.ones_like(r_sub), where=r_sub > 0)
        out[s:s + step] = (dsub * spread * np.exp(-1j * k * diff)).mean(-1)
    return out


def array_response(array: ElementArray, points_m, *, wavenumber_rad_m: float,
                   fidelity: str = "far_field", subdivisions=(4, 4), baffle: bool = True,
                   reference_m=None):
    """Complex response of a ganged array at field points, relative to a reference path.

    ``E(P) = Σ_e w_e D_e(P) e^{-jk(R_e - R_ref)} (R_ref / R_e) / Σ_e w_e``, so that the
    field at P is ``E(P) e^{-jk R_ref} / R_ref`` for a unit on-axis source level.

    Parameters
    ----------
    array : ElementArray
    points_m : array_like, shape (P, 3)
        Field points (m), sonar frame.
    wavenumber_rad_m : float
    fidelity, subdivisions, baffle
        As in :func:`element_directivity`.
    reference_m : array_like, shape (3,), optional
        Phase/spreading reference (m); default the array's phase centre.

    Returns
    -------
    ndarray, shape (P,), complex128
        1 on axis in the far field for in-phase elements of positive weight.
    """
    pts = np.asarray(points_m, float).reshape(-1, 3)
    ref = array.phase_center_m if reference_m is None else np.asarray(reference_m, float)
    d = element_directivity(array, pts, wavenumber_rad_m=wavenumber_rad_m, fidelity=fidelity,
                            subdivisions=subdivisions, baffle=baffle)
    k = float(wavenumber_rad_m)
    w = array.weight
    out = np.empty(pts.shape[0], complex)
    step = max(1, _BLOCK // array.n_elements)
    for s in range(0, pts.shape[0], step):
        diff, r_e, r_ref = _path_difference(pts[s:s + step, None, :], array.center_m[None], ref)
        spread = np.divide(r_ref, r_e, out=np.ones_like(r_e), where=r_e > 0)
        out[s:s + step] = (d[s:s + step] * w * spread * np.exp(-1j * k * diff)).sum(-1)
    return out / w.sum()


def array_pattern(array: ElementArray, azimuth_rad, elevation_rad, *, wavenumber_rad_m: float,
                  fidelity: str = "far_field", distance_m: float | None = None,
                  subdivisions=(4, 4), baffle: bool = True):
    """Complex beam pattern of a ganged array in the directions (θ, φ).

    Parameters
    ----------
    array : ElementArray
    azimuth_rad, elevation_rad : array_like, broadcastable
        Directions (rad) from the sonar-frame origin.
    wavenumber_rad_m : float
    fidelity : {"far_field", "huygens"}
    distance_m : float, optional
        Evaluate at this distance (m) from the origin with exact paths. ``None`` is the
        far-field limit (plane waves), where both fidelities coincide.
    subdivisions, baffle
        As in :func:`element_directivity`.

    Returns
    -------
    ndarray, complex128, broadcast shape of the angles
        Not normalised to its maximum: in the far field |E| <= 1 with E = 1 on axis for
        in-phase elements of positive weight. Divide by the peak for a directivity
        function E(θ, φ)/max E as the thesis plots.
    """
    u = unit_vector(azimuth_rad, elevation_rad)
    shape = u.shape[:-1]
    u = u.reshape(-1, 3)
    k = float(wavenumber_rad_m)
    if distance_m is None:
        _check_fidelity(fidelity, subdivisions)
        ex, ey = array.local_axes
        ux = u @ ex.T
        uy = u @ ey.T
        d = _piston(ux, uy, u[:, 2:3], 0.5 * k * array.width_m, 0.5 * k * array.height_m, baffle)
        # plane wave from direction u: element c leads the origin by k c·u
        phase = np.exp(1j * k * (u @ array.center_m.T))
        out = (d * array.weight * phase).sum(-1) / array.weight.sum()
        return out.reshape(shape)
    if not np.isfinite(distance_m) or distance_m <= 0:
        raise ValueError(f"distance_m must be a positive finite distance, got {distance_m!r}")
    pts = u * float(distance_m)
    out = array_response(array, pts, wavenumber_rad_m=k, fidelity=fidelity,
                         subdivisions=subdivisions, baffle=baffle, reference_m=np.zeros(3))
    return out.reshape(shape)
