"""Specular points: where a path from a source to a receiver bounces once off a curved mesh.

A one-bounce path S → X → P off a smooth surface is stationary in its length φ(X) = |X − S| +
|X − P| (Fermat): at X the bisector b = ê_S + ê_P of the two unit legs (ê_Q = (X − Q)/|X − Q|)
lies along the surface normal — the law of reflection. The mesh is read as a sampled smooth
surface: positions on its flat facets, normals interpolated from its vertex normals (Phong), so
that the normal field, and with it the surface's curvature, varies smoothly across facets.

**Search** (every stationary point, no ray density to tune). For each source–receiver pair the
tangential part of b is evaluated at every vertex; on a facet whose three vertex values can
vanish under linear interpolation, the zero is solved for and refined by Newton's method on the
smooth surface, with the analytic Hessian below. Points found from two facets are merged.
A fan of rays would find the same points only to within its spacing and can miss glints
between its rays; this search is exhaustive over facets and costs O(pairs × facets) in a compiled
loop (docs/performance.md: 10⁵ facets).

**Level** — geometrical optics through the stationary-phase evaluation of the Kirchhoff
integral p = (jk/2π) R ∫ cos θ e^{−jkφ}/(r_S r_P) dS (docs/conventions.md: e^{+jωt},
p = f e^{−jkr}/r). With H the Hessian of φ in an orthonormal tangent frame at X,

    H_ab = Σ_Q [δ_ab − (t_a·ê_Q)(t_b·ê_Q)] / r_Q + (b·n̂) II_ab,

(II the second fundamental form), the reflected field is

    p = R cos θ e^{jπ(2 − σ)/4} e^{−jkφ} / (r_S r_P √|det H|),

σ the signature of H (2 at an ordinary mirror point, 0 at a saddle, −2 past a focus). A flat
surface gives det H = cos²θ (r_S + r_P)² / (r_S r_P)², hence p = R e^{−jkφ}/(r_S + r_P): the image
source. A convex cylinder of radius ρ, the plane of incidence across its axis, gives
p = R / √((r_S + r_P)(r_S + r_P + 2 r_S r_P/(ρ cos θ))), the mirror equation (Kinsler et al.,
*Fundamentals of Acoustics*; Deschamps 1972, "Ray techniques in electromagnetics", Proc. IEEE
60(9)). The path is returned *unfolded*: an image point on the ray from S through X at the
distance r_S + r_P, with the factor A = p (r_S + r_P) e^{+jkφ} that turns the image's spreading
1/(r_S + r_P) into the curved mirror's. Near a caustic (det H → 0) geometrical optics diverges;
|A| is capped at ``focusing_limit_db`` and the capped paths are counted.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from acoustics.paths.specular_search import candidate_facets, unit_rows

__all__ = ["SpecularPoints", "specular_points", "vertex_normals"]


@dataclass(frozen=True)
class SpecularPoints:
    """One-bounce paths, one row per path, as flat arrays with an index column.

    Attributes
    ----------
    pair : ndarray of int, shape (k,)
        Index of the source–receiver pair.
    face : ndarray of int, shape (k,)
        Facet the bounce point lies on.
    point_m : ndarray, shape (k, 3)
        Bounce point X (m), on the mesh.
    normal : ndarray, shape (k, 3)
        Unit surface normal at X, on the side of the source and receiver.
    source_range_m, receiver_range_m : ndarray, shape (k,)
        r_S = |X − S| and r_P = |X − P| (m).
    cos_incidence : ndarray, shape (k,)
        cos θ, θ the angle of incidence from the normal.
    image_m : ndarray, shape (k, 3)
        The unfolded image: S + (r_S + r_P) (X − S)/r_S (m).
    divergence : ndarray, shape (k,), complex
        A = p (r_S + r_P) e^{+jkφ} / R: the curved mirror's field over the image source's,
        reflection coefficient not included (1 on a plane).
    signature : ndarray of int, shape (k,)
        σ of the Hessian: 2, 0 or −2.
    capped : ndarray of bool, shape (k,)
        |A| was limited at the focusing limit (a caustic is near).
    mesh_point_m : ndarray, shape (k, 3)
        X's foot on the facet itself (m): where rays meet the mesh (visibility checks);
        ``point_m`` is on the smooth surface, off the facet by at most its sag.
    """

    pair: np.ndarray
    face: np.ndarray
    point_m: np.ndarray
    normal: np.ndarray
    source_range_m: np.ndarray
    receiver_range_m: np.ndarray
    cos_incidence: np.ndarray
    image_m: np.ndarray
    divergence: np.ndarray
    signature: np.ndarray
    capped: np.ndarray
    mesh_point_m: np.ndarray

    def __len__(self):
        return int(self.pair.shape[0])

    @classmethod
    def empty(cls):
        z3 = np.zeros((0, 3))
        z = np.zeros(0)
        return cls(np.zeros(0, int), np.zeros(0, int), z3, z3.copy(), z, z.copy(), z.copy(),
                   z3.copy(), np.zeros(0, complex), np.zeros(0, int), np.zeros(0, bool), z3.copy())


def vertex_normals(vertices, faces):
    """Unit vertex normals (n_v, 3): the area-weighted mean of the adjacent facets' normals.

    Parameters
    ----------
    vertices : array_like, shape (n_v, 3)
    faces : array_like of int, shape (n_f, 3)
    """
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])   # |.| = 2 × area
    out = np.zeros_like(v)
    for j in range(3):
        np.add.at(out, f[:, j], fn)
    norm = np.linalg.norm(out, axis=1)
    return out / np.where(norm > 0, norm, 1.0)[:, None]


#: unit rows (the search's helper)
_unit = unit_rows


def _geometry(V, F, N, face, st, S, P):
    """Point, normal, tangents, Hessian and gradient on the smooth surface of each candidate."""
    a, b, c = V[F[face, 0]], V[F[face, 1]], V[F[face, 2]]
    e = np.stack([b - a, c - a], axis=1)                               # (k, 2, 3)
    na, nb_, nc = N[F[face, 0]], N[F[face, 1]], N[F[face, 2]]
    dn = np.stack([nb_ - na, nc - na], axis=1)                          # (k, 2, 3)
    flat = a + st[:, :1] * e[:, 0] + st[:, 1:] * e[:, 1]
    # Phong tessellation with α = ½ (Boubekeur & Alexa 2008): the mean of the projections onto
    # the vertices' tangent planes lifts the facet to the smooth surface — on a circle of radius
    # R it puts the chord's midpoint at the arc (sag d²/8R) to second order
    bary = np.column_stack([1 - st[:, 0] - st[:, 1], st[:, 0], st[:, 1]])
    lift = np.zeros_like(flat)
    for i, (v, nv) in enumerate(((a, na), (b, nb_), (c, nc))):
        lift -= 0.5 * bary[:, i:i + 1] * np.einsum("kj,kj->k", flat - v, nv)[:, None] * nv
    x = flat + lift
    nu = na + st[:, :1] * dn[:, 0] + st[:, 1:] * dn[:, 1]
    nlen = np.linalg.norm(nu, axis=1)
    n = nu / np.where(nlen > 0, nlen, 1.0)[:, None]
    tan = e - np.einsum("kaj,kj->ka", e, n)[..., None] * n[:, None, :]   # tangents T_a
    dnu = (dn - np.einsum("kaj,kj->ka", dn, n)[..., None] * n[:, None, :]) / np.where(
        nlen > 0, nlen, 1.0)[:, None, None]                            # ∂n/∂u_a
    ii = -0.5 * (np.einsum("kaj,kbj->kab", dnu, tan) + np.einsum("kbj,kaj->kab", dnu, tan))
    legs = []
    bis = np.zeros_like(x)
    hess = np.zeros((x.shape[0], 2, 2))
    gram = np.einsum("kaj,kbj->kab", tan, tan)
    for q in (S, P):
        d = x - q
        r = np.linalg.norm(d, axis=1)
        u = d / np.where(r > 0, r, 1.0)[:, None]
        legs.append((r, u))
        bis += u
        tu = np.einsum("kaj,kj->ka", tan, u)
        hess += (gram - tu[:, :, None] * tu[:, None, :]) / np.where(r > 0, r, np.inf)[:, None, None]
    bn = np.einsum("kj,kj->k", bis, n)
    hess += bn[:, None, None] * ii
    grad = np.einsum("kaj,kj->ka", tan, bis)
    return x, n, tan, hess, grad, legs, bn, flat


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _newton_on_mesh(V, F, N, face, st, S, P, iterations):
    """Newton's steps of :func:`specular_points` on the mesh's smooth surface, one candidate at
    a time (the geometry of :func:`_geometry`): each stops once its step is below 1e-12 of its
    facet, where the reference loop steps every candidate until all have. Returns the final
    (s, t), shape (k, 2)."""
    out = st.copy()
    for k in range(face.shape[0]):
        a, b, c = F[face[k], 0], F[face[k], 1], F[face[k], 2]
        e = np.empty((2, 3))
        dn = np.empty((2, 3))
        for j in range(3):
            e[0, j] = V[b, j] - V[a, j]
            e[1, j] = V[c, j] - V[a, j]
            dn[0, j] = N[b, j] - N[a, j]
            dn[1, j] = N[c, j] - N[a, j]
        s, t = out[k, 0], out[k, 1]
        for _ in range(iterations):
            w = (1.0 - s - t, s, t)
            flat = np.empty(3)
            for j in range(3):
                flat[j] = V[a, j] + s * e[0, j] + t * e[1, j]
            x = flat.copy()
            for i in range(3):
                v = (a, b, c)[i]
                h = 0.0
                for j in range(3):
                    h += (flat[j] - V[v, j]) * N[v, j]
                for j in range(3):
                    x[j] -= 0.5 * w[i] * h * N[v, j]
            nu = np.empty(3)
            for j in range(3):
                nu[j] = N[a, j] + s * dn[0, j] + t * dn[1, j]
            nlen = np.sqrt(nu[0] * nu[0] + nu[1] * nu[1] + nu[2] * nu[2])
            inv = 1.0 / nlen if nlen > 0 else 1.0
            n = nu * inv
            tan = np.empty((2, 3))
            dnu = np.empty((2, 3))
            for q in range(2):
                en = e[q, 0] * n[0] + e[q, 1] * n[1] + e[q, 2] * n[2]
                dd = dn[q, 0] * n[0] + dn[q, 1] * n[1] + dn[q, 2] * n[2]
                for j in range(3):
                    tan[q, j] = e[q, j] - en * n[j]
                    dnu[q, j] = (dn[q, j] - dd * n[j]) * inv
            h00 = h01 = h11 = 0.0
            bis = np.zeros(3)
            for w_ in range(2):
                Q = S[k] if w_ == 0 else P[k]
                d0, d1, d2 = x[0] - Q[0], x[1] - Q[1], x[2] - Q[2]
                r = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if r > 0:
                    u0, u1, u2 = d0 / r, d1 / r, d2 / r
                    bis[0] += u0
                    bis[1] += u1
                    bis[2] += u2
                    t0 = tan[0, 0] * u0 + tan[0, 1] * u1 + tan[0, 2] * u2
                    t1 = tan[1, 0] * u0 + tan[1, 1] * u1 + tan[1, 2] * u2
                    g00 = tan[0, 0] * tan[0, 0] + tan[0, 1] * tan[0, 1] + tan[0, 2] * tan[0, 2]
                    g01 = tan[0, 0] * tan[1, 0] + tan[0, 1] * tan[1, 1] + tan[0, 2] * tan[1, 2]
                    g11 = tan[1, 0] * tan[1, 0] + tan[1, 1] * tan[1, 1] + tan[1, 2] * tan[1, 2]
                    h00 += (g00 - t0 * t0) / r
                    h01 += (g01 - t0 * t1) / r
                    h11 += (g11 - t1 * t1) / r
                else:
                    bis[0] += d0
                    bis[1] += d1
                    bis[2] += d2
            bn = bis[0] * n[0] + bis[1] * n[1] + bis[2] * n[2]
            ii00 = -(dnu[0, 0] * tan[0, 0] + dnu[0, 1] * tan[0, 1] + dnu[0, 2] * tan[0, 2])
            ii11 = -(dnu[1, 0] * tan[1, 0] + dnu[1, 1] * tan[1, 1] + dnu[1, 2] * tan[1, 2])
            ii01 = -0.5 * ((dnu[0, 0] * tan[1, 0] + dnu[0, 1] * tan[1, 1] + dnu[0, 2] * tan[1, 2])
                           + (dnu[1, 0] * tan[0, 0] + dnu[1, 1] * tan[0, 1] + dnu[1, 2] * tan[0, 2]))
            h00 += bn * ii00
            h01 += bn * ii01
            h11 += bn * ii11
            g0 = tan[0, 0] * bis[0] + tan[0, 1] * bis[1] + tan[0, 2] * bis[2]
            g1 = tan[1, 0] * bis[0] + tan[1, 1] * bis[1] + tan[1, 2] * bis[2]
            det = h00 * h11 - h01 * h01
            if not abs(det) > 0.0:
                break                       # no step: the reference steps it by zero
            ds = -(h11 * g0 - h01 * g1) / det
            dt = -(-h01 * g0 + h00 * g1) / det
            # never farther than the facet's own size per step (as the reference)
            big = max(abs(ds), abs(dt))
            scale = max(1.0, big)
            s += ds / scale
            t += dt / scale
            if big < 1e-12:
                break
        out[k, 0] = s
        out[k, 1] = t
    return out


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _merge_repeats(pair, x, scale):
    """Rows (sorted by pair, then path length) that repeat a kept row among the last 8 kept:
    the same pair and a point within 1e-3 of its facet's edge (+ 1 nm). Returns the mask of
    the rows kept."""
    keep = np.zeros(pair.shape[0], np.bool_)
    kept = np.empty(pair.shape[0], np.int64)
    n = 0
    for i in range(pair.shape[0]):
        dup = False
        for q in range(max(0, n - 8), n):
            u = kept[q]
            if pair[u] == pair[i]:
                d0, d1, d2 = x[u, 0] - x[i, 0], x[u, 1] - x[i, 1], x[u, 2] - x[i, 2]
                if np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) < 1e-3 * scale[i] + 1e-9:
                    dup = True
                    break
        if not dup:
            keep[i] = True
            kept[n] = i
            n += 1
    return keep


def _height_field_geometry(hf, xy, S, P):
    """As :func:`_geometry` on an exact height field z(x, y) (its own frame): point, normal,
    tangents X_x, X_y, Hessian of φ in (x, y), gradient, legs, b·n."""
    z, zx, zy, zxx, zxy, zyy = hf(xy[:, 0], xy[:, 1])
    x = np.column_stack([xy, z])
    one, nil = np.ones_like(z), np.zeros_like(z)
    tan = np.stack([np.column_stack([one, nil, zx]), np.column_stack([nil, one, zy])], axis=1)
    n = _unit(np.column_stack([-zx, -zy, one]))
    legs, bis = [], np.zeros_like(x)
    gram = np.einsum("kaj,kbj->kab", tan, tan)
    hess = np.zeros((x.shape[0], 2, 2))
    for q in (S, P):
        d = x - q
        r = np.linalg.norm(d, axis=1)
        u = d / np.where(r > 0, r, 1.0)[:, None]
        legs.append((r, u))
        bis += u
        tu = np.einsum("kaj,kj->ka", tan, u)
        hess += (gram - tu[:, :, None] * tu[:, None, :]) / np.where(r > 0, r, np.inf)[:, None, None]
    # exact second derivative: Σ ê·X_ab = b_z z_ab (X_ab = (0, 0, z_ab))
    hess += bis[:, 2, None, None] * np.stack([np.stack([zxx, zxy], -1), np.stack([zxy, zyy], -1)], 1)
    grad = np.einsum("kaj,kj->ka", tan, bis)
    return x, n, tan, hess, grad, legs, np.einsum("kj,kj->k", bis, n)


def _inside_xy(tri_xy, xy, eps):
    """Whether points lie in triangles' (x, y) projections; and the barycentric (s, t)."""
    a, b, c = tri_xy[:, 0], tri_xy[:, 1], tri_xy[:, 2]
    e1, e2, d = b - a, c - a, xy - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    det = np.where(det != 0, det, 1.0)
    s = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / det
    t = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / det
    return (s >= -eps) & (t >= -eps) & (s + t <= 1 + eps), np.column_stack([s, t])




def specular_points(vertices, faces, normals, sources_m, receivers_m, *, wavenumber=None,
                    newton_iterations: int = 8, focusing_limit_db: float = 20.0,
                    search_tolerance: float = 0.1, height_field=None,
                    cull: bool = True, window=None, blocks=None,
                    near_facets: bool = False) -> SpecularPoints:
    """Every one-bounce specular path off a mesh for each source–receiver pair.

    Parameters
    ----------
    vertices : array_like, shape (n_v, 3)
        Mesh vertices (m).
    faces : array_like of int, shape (n_f, 3)
    normals : array_like, shape (n_v, 3)
        Unit vertex normals of the smooth surface the mesh samples (:func:`vertex_normals`
        when only the mesh is known).
    sources_m, receivers_m : array_like, shape (m, 3)
        The pairs' end points (m).
    wavenumber : float, optional
        Unused by geometry; accepted for symmetry with callers that pass it.
    newton_iterations : int
        Refinement steps on the smooth surface (0: the linear estimate on the facet).
    focusing_limit_db : float
        Largest |A| (dB) a path may have; geometrical optics diverges at a caustic.
    search_tolerance : float
        Facets are searched this fraction beyond their edges (points found twice are merged).
    cull : bool
        Skip blocks of 16 neighbouring facets, and nodes of blocks, where the legs' bisector
        cannot meet the surface normal (a bound, not an approximation: the bounce points are
        those of the exhaustive search; with Newton steps on the mesh, a tight bound that
        also leaves out facets whose candidates would fail the residual test, else a 0.1 rad
        margin around the blocks' normal cones); False tests every facet (the reference the
        tests compare with).
    window : (ndarray (3,), ndarray (3, 3), (az_lo, az_hi, el_lo, el_hi)), optional
        Search only blocks of facets that reach into this angular window (rad) seen from its
        origin (m), directions in the axes of the rotation's columns (a transmitter's fan:
        ``effects.specular.beam_level_db``); needs ``cull``. None: everywhere.
    near_facets : bool
        With ``window``: a block of facets seen from the window's origin under more than
        0.05 rad is searched only in its facets whose own sphere reaches into the window
        (``effects.specular.near_facets``); else in all of them.
    height_field : (callable, ndarray (4, 4)), optional
        The exact surface the mesh samples, as ``z, z_x, z_y, z_xx, z_xy, z_yy = f(x, y)`` in
        its own frame, and the rigid placement of that frame in the mesh's. Bounce points are
        then refined, and their levels taken, on it (the mesh only finds them and, with its
        facets, decides visibility): exact at any mesh resolution. A third item, (slope,
        curvature): bounds of the field's |∇z| and of its Hessian's spectral norm (1/m; for a
        sum of waves Σ a|k| and Σ a|k|²): the blocks are then skipped by the tight bound grown
        by how far a refined point may lie from its facet (a bound: the points of the
        exhaustive search), else by the loose 0.1 rad margin.
    blocks : tuple, optional
        The mesh's :func:`acoustics.paths.specular_search.search_blocks` (blocks, unit
        normals), kept by the caller (a floor's tiles keep theirs, acoustics/paths/tiles.py);
        default: made here and cached for the last meshes searched.

    Returns
    -------
    SpecularPoints
        Rows sorted by pair, then path length.
    """
    V = np.ascontiguousarray(np.asarray(vertices, float))
    F = np.ascontiguousarray(np.asarray(faces, np.int64))
    S = np.ascontiguousarray(np.asarray(sources_m, float).reshape(-1, 3))
    P = np.ascontiguousarray(np.asarray(receivers_m, float).reshape(-1, 3))
    if S.shape != P.shape:
        raise ValueError("sources_m and receivers_m must have the same shape (m, 3)")
    if S.shape[0] == 0 or F.shape[0] == 0:
        return SpecularPoints.empty()
    if not (np.all(np.isfinite(S)) and np.all(np.isfinite(P))):
        raise ValueError("specular_points: sources and receivers must be finite")
    rot = None
    bound = None
    if height_field is not None:
        f_hf, place = height_field[:2]
        rot, shift = np.asarray(place, float)[:3, :3], np.asarray(place, float)[:3, 3]
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-9):
            rot = None                        # scaled: the mesh is the best we have
        elif len(height_field) > 2 and height_field[2] is not None and cull and newton_iterations > 0:
            # the field's slope and curvature bound how far a refined point may be from its
            # facet's, in place and in normal: the tight block bound, grown by that
            slope, curvature = (float(x) for x in height_field[2])
            Vo = (V - shift) @ rot
            z, z_x, z_y = f_hf(Vo[:, 0], Vo[:, 1])[:3]
            n_field = _unit(np.column_stack([-z_x, -z_y, np.ones_like(z_x)])) @ rot.T
            off = float(np.max(np.abs(z - Vo[:, 2]))) if len(z) else 0.0
            if np.isfinite(off) and np.all(np.isfinite(n_field)):
                bound = (np.ascontiguousarray(n_field), off, slope, curvature, rot[:, 2])
    # the tight bound holds for points refined on the mesh's smooth surface and tested
    N, pair, face, st = candidate_facets(V, F, normals, S, P, tolerance=search_tolerance,
                                         cull=cull, window=window, blocks=blocks,
                                         tight=rot is None and newton_iterations > 0,
                                         height_bound=bound, near_facets=near_facets)
    Sq, Pq = S[pair], P[pair]
    if rot is not None:
        # Newton on the exact surface in its own frame, from the facet's estimate
        Vo = (V - shift) @ rot
        So, Po = (Sq - shift) @ rot, (Pq - shift) @ rot
        tri = Vo[F[face]]
        start = tri[:, 0] + st[:, :1] * (tri[:, 1] - tri[:, 0]) + st[:, 1:] * (tri[:, 2] - tri[:, 0])
        xy = start[:, :2].copy()
        step_max = np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1)
        active = np.arange(xy.shape[0])
        dup = np.zeros(xy.shape[0], bool)
        for it in range(newton_iterations):
            if it == 2:
                # a bounce point is found from each facet near it: after two steps its copies
                # agree to far below 0.1 mm (quadratic convergence), so one goes on
                cell = np.round(xy[active] / 1e-4).astype(np.int64)
                _, first = np.unique(np.column_stack([pair[active], cell]), axis=0,
                                     return_index=True)
                keep_one = np.zeros(active.size, bool)
                keep_one[first] = True
                dup[active[~keep_one]] = True
                active = active[keep_one]
            # only the points still moving: the exact surface costs (points × waves) per step
            _, _, _, hess, grad, _, _ = _height_field_geometry(f_hf, xy[active], So[active],
                                                               Po[active])
            det = hess[:, 0, 0] * hess[:, 1, 1] - hess[:, 0, 1] * hess[:, 1, 0]
            ok = np.abs(det) > 0
            safe = np.where(ok, det, 1.0)
            dx = -(hess[:, 1, 1] * grad[:, 0] - hess[:, 0, 1] * grad[:, 1]) / safe
            dy = -(-hess[:, 1, 0] * grad[:, 0] + hess[:, 0, 0] * grad[:, 1]) / safe
            step = np.column_stack([np.where(ok, dx, 0.0), np.where(ok, dy, 0.0)])
            big = np.linalg.norm(step, axis=1)
            xy[active] += step * np.minimum(1.0, step_max[active] / np.maximum(big, 1e-300))[:, None]
            active = active[big >= 1e-13]
            if active.size == 0:
                break
        x, n, tan, hess, grad, legs, bn = _height_field_geometry(f_hf, xy, So, Po)
        # a point converged from a neighbour's estimate is as good (duplicates are merged)
        inside, st2 = _inside_xy(tri[:, :, :2], xy, 0.5)
        inside &= ~dup
        flat = tri[:, 0] + st2[:, :1] * (tri[:, 1] - tri[:, 0]) + st2[:, 1:] * (tri[:, 2] - tri[:, 0])
        # back to the mesh's frame (vectors rotate; lengths, Hessian and b·n do not change)
        x, flat = x @ rot.T + shift, flat @ rot.T + shift
        n, tan = n @ rot.T, tan @ rot.T
        legs = [(r, u @ rot.T) for r, u in legs]
        (r_s, u_s), (r_p, u_p) = legs
    else:
        if cull:
            # the searched path's steps in a compiled loop; the exhaustive reference below
            st = _newton_on_mesh(V, F, N, face, np.ascontiguousarray(st), Sq, Pq,
                                 newton_iterations)
        for _ in range(0 if cull else newton_iterations):
            x, n, tan, hess, grad, legs, bn, _ = _geometry(V, F, N, face, st, Sq, Pq)
            det = hess[:, 0, 0] * hess[:, 1, 1] - hess[:, 0, 1] * hess[:, 1, 0]
            ok = np.abs(det) > 0
            safe = np.where(ok, det, 1.0)
            ds = -(hess[:, 1, 1] * grad[:, 0] - hess[:, 0, 1] * grad[:, 1]) / safe
            dt = -(-hess[:, 1, 0] * grad[:, 0] + hess[:, 0, 0] * grad[:, 1]) / safe
            step = np.column_stack([np.where(ok, ds, 0.0), np.where(ok, dt, 0.0)])
            # never farther than the facet's own size per step: Newton from a poor start must not
            # jump to another sheet of the surface
            big = np.max(np.abs(step), axis=1)
            st = st + step / np.maximum(1.0, big)[:, None]
            if np.all(big < 1e-12):
                break
        x, n, tan, hess, grad, legs, bn, flat = _geometry(V, F, N, face, st, Sq, Pq)
        (r_s, u_s), (r_p, u_p) = legs
        eps = 1e-6
        inside = (st[:, 0] >= -eps) & (st[:, 1] >= -eps) & (st[:, 0] + st[:, 1] <= 1 + eps)
    # the law of reflection holds (the residual is a sine: |b_t| / |b|) ...
    bnorm = np.linalg.norm(u_s + u_p, axis=1)
    resid = np.linalg.norm((u_s + u_p) - bn[:, None] * n, axis=1) / np.where(bnorm > 0, bnorm, 1.0)
    # ... source and receiver on the same side, off the surface
    cs, cp = -np.einsum("kj,kj->k", u_s, n), -np.einsum("kj,kj->k", u_p, n)
    same_side = (cs * cp > 0) & (r_s > 0) & (r_p > 0)
    keep = inside & same_side & (resid < 1e-3) & np.all(np.isfinite(x), axis=1)
    if newton_iterations == 0:
        keep = inside & same_side & np.all(np.isfinite(x), axis=1)
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        return SpecularPoints.empty()
    # merge points found from neighbouring facets (same pair, same point)
    scale = np.linalg.norm(V[F[face[idx], 1]] - V[F[face[idx], 0]], axis=1)
    order = np.lexsort((r_s[idx] + r_p[idx], pair[idx]))
    idx, scale = idx[order], scale[order]
    idx = idx[_merge_repeats(pair[idx], np.ascontiguousarray(x[idx]), scale)]
    sign = np.where(cs[idx] > 0, 1.0, -1.0)
    nrm = n[idx] * sign[:, None]
    cos_inc = np.abs(cs[idx])
    h = hess[idx]
    # orthonormal-frame determinant: det(H_param) / |T1 × T2|²
    area = np.linalg.norm(np.cross(tan[idx, 0], tan[idx, 1]), axis=1)
    det_param = h[:, 0, 0] * h[:, 1, 1] - h[:, 0, 1] * h[:, 1, 0]
    tr = h[:, 0, 0] + h[:, 1, 1]
    sig = np.where(det_param < 0, 0, np.where(tr > 0, 2, -2))
    rs, rp = r_s[idx], r_p[idx]
    total = rs + rp
    root = np.sqrt(np.abs(det_param)) / np.where(area > 0, area, 1.0)
    limit = 10.0 ** (focusing_limit_db / 20.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = cos_inc * total / (rs * rp * root)
    capped = ~(mag <= limit)
    mag = np.where(capped, limit, mag)
    div = mag * np.exp(1j * np.pi * (2 - sig) / 4)
    image = S[pair[idx]] + (total / rs)[:, None] * (x[idx] - S[pair[idx]])
    return SpecularPoints(pair[idx], face[idx], x[idx], nrm, rs, rp, cos_inc, image, div,
                          sig.astype(int), capped, flat[idx])
