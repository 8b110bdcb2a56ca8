"""The candidate search of :func:`acoustics.paths.specular.specular_points`: the facets on
which the legs' bisector may lie along the surface normal, for every source–receiver pair.

The tangential part of the bisector b = ê_S + ê_P is evaluated at a facet's vertices; where its
linear interpolant can vanish on the facet (both components change sign, ``tolerance`` beyond
its edges), the facet is a candidate, refined afterwards by Newton's method on the smooth
surface. :func:`_candidates` tests every facet for every pair (the reference);
:func:`_candidates_tree` skips blocks of 16 neighbouring facets, and nodes of a tree over the
blocks, where the reflection law cannot hold, the pairs in groups that walk the tree once
(docs/accuracy.md, "Specular search": the same paths as every facet).
"""
from __future__ import annotations

import threading

import numba as nb
import numpy as np

from acoustics.paths.specular_field import height_field_blocks
from acoustics.paths.specular_blocks import block_spheres, block_vertices, facet_cells, facet_sag
from acoustics.paths.specular_window import window_blocks

__all__ = ["candidate_facets", "search_blocks", "unit_rows"]


def unit_rows(x):
    """``x`` (..., 3) with each row scaled to unit length (zero rows left at zero)."""
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    return x / np.where(n > 0, n, 1.0)


_unit = unit_rows


def candidate_facets(vertices, faces, normals, sources_m, receivers_m, *, tolerance: float,
                     cull: bool = True, window=None, tight: bool = True, blocks=None,
                     height_bound=None, near_facets: bool = False):
    """Candidate bounce facets of every pair.

    Parameters
    ----------
    vertices : ndarray, shape (n_v, 3), float64, C-contiguous
        Mesh vertices (m).
    faces : ndarray of int64, shape (n_f, 3), C-contiguous
    normals : array_like, shape (n_v, 3)
        Vertex normals (any length; the unit ones are returned).
    sources_m, receivers_m : ndarray, shape (m, 3), C-contiguous
        The pairs' end points (m).
    tolerance : float
        Facets are searched this fraction beyond their edges.
    cull : bool
        The blocked, tree-walked search (False: every facet, the reference).
    window : optional
        As :func:`acoustics.paths.specular.specular_points`' ``window`` (needs ``cull``).
    near_facets : bool
        With a window: a block seen under more than ``_NEAR_BLOCK_RAD`` from its origin is
        windowed facet by facet (acoustics/paths/specular_window.py); else by its sphere.
    tight : bool
        The tight block bound (candidates refined on the mesh's smooth surface and tested
        there); else the cone with a 0.1 rad margin.
    blocks : tuple, optional
        The mesh's :func:`search_blocks` (blocks, unit normals), kept by the caller (a floor's
        tiles keep theirs, acoustics/paths/tiles.py); default: made here and cached for the
        last meshes searched.
    height_bound : (ndarray (n_v, 3), float, float, float, ndarray (3,)), optional
        Candidates refined on an exact height field (``specular_points``' ``height_field``):
        the field's unit normals at the vertices (mesh frame), the most the vertices lie off
        it (m), its largest slope and its largest curvature (the spectral norm of its Hessian,
        1/m), its z axis in the mesh's frame. The blocks are then skipped by the tight bound, grown by how far a refined point
        may lie from its facet (acoustics/paths/specular_field.py); ``tight`` is ignored.

    Returns
    -------
    unit_normals : ndarray, shape (n_v, 3)
    pair, face : ndarray of int64, shape (k,)
    st : ndarray, shape (k, 2)
        Barycentric (s, t) of each candidate's linear estimate on its facet; rows by pair,
        then facet in the search's order.
    """
    V, F, S, P = vertices, faces, sources_m, receivers_m
    normals = np.asarray(normals, float)
    cap = max(256, 32 * S.shape[0])      # a wavy sea: a few glints per pair
    if not cull:
        N = np.ascontiguousarray(_unit(normals))
        while True:
            pair = np.empty(cap, np.int64)
            face = np.empty(cap, np.int64)
            st = np.empty((cap, 2))
            k = _candidates(V, F, N, S, P, tolerance, cap, pair, face, st)
            if k <= cap:
                return N, pair[:k], face[:k], st[:k]
            cap = k
    if blocks is not None:
        blocks, N = blocks                  # the caller's, with the unit normals they were made from
    else:
        blocks, N = _blocks_of(V, F, normals)
    allowed = np.ones(blocks[1].size - 1, np.uint8)
    facet_ok = None
    if window is not None:
        allowed, facet_ok = (window_blocks(blocks, window, V, F) if near_facets
                             else window_blocks(blocks, window))
    if not allowed.any():
        return N, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2))
    if height_bound is not None:       # the same spheres (the window's), grown bounds
        blocks = _field_blocks_of(V, F, blocks, *height_bound)
        tight = True
    pair, face, st = _search_split(V, F, N, S, P, tolerance, blocks, cap, allowed, tight)
    if facet_ok is not None:
        keep = facet_ok[face]
        pair, face, st = pair[keep], face[keep], st[keep]
    return N, pair, face, st


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _residual(V, N, S, P, v):
    """Tangential part of the bisector ê_S + ê_P at vertex v (three floats, no allocation)."""
    bx = by = bz = 0.0
    for w in range(2):
        Q = S if w == 0 else P
        dx, dy, dz = V[v, 0] - Q[0], V[v, 1] - Q[1], V[v, 2] - Q[2]
        r = np.sqrt(dx * dx + dy * dy + dz * dz)
        if r > 0.0:
            bx += dx / r
            by += dy / r
            bz += dz / r
    bn = bx * N[v, 0] + by * N[v, 1] + bz * N[v, 2]
    return bx - bn * N[v, 0], by - bn * N[v, 1], bz - bn * N[v, 2]


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _facet_basis(V, a, b, c):
    """An orthonormal basis (u1, u2) of facet (a, b, c)'s plane, u1 along its first edge:
    (ok, u1x, u1y, u1z, u2x, u2y, u2z); not ok for a degenerate facet."""
    e1x, e1y, e1z = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
    e2x, e2y, e2z = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
    l1 = np.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
    if l1 == 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    u1x, u1y, u1z = e1x / l1, e1y / l1, e1z / l1
    d = e2x * u1x + e2y * u1y + e2z * u1z
    wx, wy, wz = e2x - d * u1x, e2y - d * u1y, e2z - d * u1z
    l2 = np.sqrt(wx * wx + wy * wy + wz * wz)
    if l2 == 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    return True, u1x, u1y, u1z, wx / l2, wy / l2, wz / l2


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _facet_solve(u1x, u1y, u1z, u2x, u2y, u2z, ra, rb, rc, tol):
    """:func:`_facet_zero` in a facet's basis (:func:`_facet_basis`)."""
    # the three vertex residuals in the facet's basis: both components must change sign
    pa0 = ra[0] * u1x + ra[1] * u1y + ra[2] * u1z
    pb0 = rb[0] * u1x + rb[1] * u1y + rb[2] * u1z
    pc0 = rc[0] * u1x + rc[1] * u1y + rc[2] * u1z
    lo, hi = min(pa0, pb0, pc0), max(pa0, pb0, pc0)
    if lo > tol * (hi - lo) or hi < -tol * (hi - lo):
        return False, 0.0, 0.0
    pa1 = ra[0] * u2x + ra[1] * u2y + ra[2] * u2z
    pb1 = rb[0] * u2x + rb[1] * u2y + rb[2] * u2z
    pc1 = rc[0] * u2x + rc[1] * u2y + rc[2] * u2z
    lo, hi = min(pa1, pb1, pc1), max(pa1, pb1, pc1)
    if lo > tol * (hi - lo) or hi < -tol * (hi - lo):
        return False, 0.0, 0.0
    m00, m01 = pb0 - pa0, pc0 - pa0
    m10, m11 = pb1 - pa1, pc1 - pa1
    det = m00 * m11 - m01 * m10
    if det == 0.0:
        return False, 0.0, 0.0
    s = (-pa0 * m11 + pa1 * m01) / det
    t = (-pa1 * m00 + pa0 * m10) / det
    if s < -tol or t < -tol or s + t > 1.0 + tol:
        return False, s, t
    return True, s, t


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _facet_zero(V, a, b, c, ra, rb, rc, tol):
    """Where on facet (a, b, c) the linear interpolant of the vertex residuals ``ra``, ``rb``,
    ``rc`` (3-tuples) vanishes, ``tol`` beyond its edges: (found, s, t) in its barycentric
    coordinates."""
    ok, u1x, u1y, u1z, u2x, u2y, u2z = _facet_basis(V, a, b, c)
    if not ok:
        return False, 0.0, 0.0
    return _facet_solve(u1x, u1y, u1z, u2x, u2y, u2z, ra, rb, rc, tol)


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _keep(k, cap, pair, face, s, t, out_pair, out_face, out_st):
    """Write candidate k (if there is room) and return the count: rows past ``cap`` are counted,
    so the caller can grow its buffers and search again."""
    if k < cap:
        out_pair[k] = pair
        out_face[k] = face
        out_st[k, 0] = s
        out_st[k, 1] = t
    return k + 1


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _candidates(V, F, N, S, P, tol, cap, out_pair, out_face, out_st):
    """Facets on which the linearly interpolated tangential bisector vanishes, for every pair,
    every facet tested (the reference of :func:`_candidates_tree`); returns the number found
    (rows past ``cap`` are counted, not written)."""
    tang = np.empty((V.shape[0], 3))
    k = 0
    for j in range(S.shape[0]):
        for v in range(V.shape[0]):      # each vertex's residual once per pair
            tang[v, 0], tang[v, 1], tang[v, 2] = _residual(V, N, S[j], P[j], v)
        for f in range(F.shape[0]):
            a, b, c = F[f, 0], F[f, 1], F[f, 2]
            ok, s, t = _facet_zero(V, a, b, c, (tang[a, 0], tang[a, 1], tang[a, 2]),
                                   (tang[b, 0], tang[b, 1], tang[b, 2]),
                                   (tang[c, 0], tang[c, 1], tang[c, 2]), tol)
            if ok:
                k = _keep(k, cap, j, f, s, t, out_pair, out_face, out_st)
    return k


#: the bound of the tight block test (rad): a bounce point is kept when the legs' bisector is
#: within asin(1e-3) of the surface normal there (``specular_points``' residual test)
_TIGHT_MARGIN = 2e-3
#: the fixed margin (rad) of the loose block test, where a candidate is kept without a residual
#: test (no Newton steps) or is refined off the mesh (an exact height field)
_LOOSE_MARGIN = 0.1


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _chord(x):
    """The most a unit vector from a point turns, 2 sin(½ asin x), as the point's target moves
    within a sphere of radius ρ seen at distance r > ρ (x = ρ/r < 1); written without the
    cancellation of 1 − √(1 − x²)."""
    return x * np.sqrt(2.0 / (1.0 + np.sqrt(1.0 - x * x))) * (1.0 + 1e-12)


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _skip_tight(S, P, cx, cy, cz, rho, rho_p, ax, ay, az, cos_a, sin_a):
    """Whether no point of the sphere (centre c, radius ``rho``) can hold a bisector
    ê_S + ê_P within ``spread`` + ``margin`` of the cone axis (±a), for any P within
    ``rho_p`` − ``rho`` of the given one: the bisector at the centre is farther from the axis
    than the cone, the margin and the most it turns (each unit leg by at most the chord of the
    angular radius of what moves: the point, and on P's leg P as well). ``cos_a``, ``sin_a``:
    of a = spread + margin; the angle test ang > a + asin(x) (x = turn / |b|) as
    cos(ang) < cos a √(1−x²) − sin a · x, never true once a + asin(x) ≥ π/2."""
    if cos_a <= 0.0:
        return False
    dx, dy, dz = cx - S[0], cy - S[1], cz - S[2]
    ex, ey, ez = cx - P[0], cy - P[1], cz - P[2]
    r_s = np.sqrt(dx * dx + dy * dy + dz * dz)
    r_p = np.sqrt(ex * ex + ey * ey + ez * ez)
    if r_s <= rho or r_p <= rho_p:
        return False
    bx, by, bz = dx / r_s + ex / r_p, dy / r_s + ey / r_p, dz / r_s + ez / r_p
    m = np.sqrt(bx * bx + by * by + bz * bz)
    turn = _chord(rho / r_s) + _chord(rho_p / r_p)
    if m <= turn:
        return False
    x = turn / m
    return abs(bx * ax + by * ay + bz * az) / m < cos_a * np.sqrt(1.0 - x * x) - sin_a * x


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _skip_node_loose(S, P, cx, cy, cz, rho, rho_p, ax, ay, az, cos_a, sin_a):
    """Whether the loose block test (:func:`_skip_block_loose`) skips every block of a node
    (its blocks' spheres inside the node's, their normal cones inside its cone) for every P
    within ``rho_p`` − ``rho`` of the given one: the node's bisector is farther from its cone
    than the margin, the most a block's centre and P's move turn it (T, the loose bound
    2ρ/(r − ρ) per leg) and the most the block's own test then adds (asin T/(m − T)), with
    1e-9 rad for rounding (``cos_a``, ``sin_a``: of a = spread + margin + 1e-9; the angles
    added as in :func:`_skip_tight`)."""
    if cos_a <= 0.0:
        return False
    dx, dy, dz = cx - S[0], cy - S[1], cz - S[2]
    ex, ey, ez = cx - P[0], cy - P[1], cz - P[2]
    r_s = np.sqrt(dx * dx + dy * dy + dz * dz)
    r_p = np.sqrt(ex * ex + ey * ey + ez * ez)
    if r_s <= 3.0 * rho or r_p <= 3.0 * rho_p:
        return False
    bx, by, bz = dx / r_s + ex / r_p, dy / r_s + ey / r_p, dz / r_s + ez / r_p
    m = np.sqrt(bx * bx + by * by + bz * bz)
    turn = 2.0 * rho / (r_s - rho) + 2.0 * rho_p / (r_p - rho_p)
    if m <= 2.0 * turn:
        return False
    x1, x2 = turn / m, turn / (m - turn)
    c1, s1 = np.sqrt(1.0 - x1 * x1), np.sqrt(1.0 - x2 * x2)
    c = cos_a * c1 - sin_a * x1                 # cos, sin of a + asin(x1)
    s = sin_a * c1 + cos_a * x1
    if c <= 0.0:
        return False
    return abs(bx * ax + by * ay + bz * az) / m < c * s1 - s * x2


@nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _skip_block_loose(S, P, cx, cy, cz, rho, ax, ay, az, cos_a, sin_a, wide, margin_ok):
    """The loose block test: the angle test ang > a + asin(x) (a = cone + margin,
    x = turn / |b|, turn = 2ρ/(r − ρ) per leg) as cos(ang) < cos a √(1−x²) − sin a · x, valid
    while a + asin(x) < π (``wide`` blocks, a ≥ π/2, may exceed it)."""
    dx, dy, dz = cx - S[0], cy - S[1], cz - S[2]
    r = np.sqrt(dx * dx + dy * dy + dz * dz)
    inv = 1.0 / max(r, 1e-300)
    s0, s1, s2 = dx * inv, dy * inv, dz * inv
    s3 = 2.0 * rho / max(r - rho, 1e-300)
    near_s = r <= 2.0 * rho
    ex, ey, ez = cx - P[0], cy - P[1], cz - P[2]
    r_p = np.sqrt(ex * ex + ey * ey + ez * ez)
    near = near_s | (r_p <= 2.0 * rho)
    i_p = 1.0 / max(r_p, 1e-300)
    bx = s0 + ex * i_p
    by = s1 + ey * i_p
    bz = s2 + ez * i_p
    turn = s3 + 2.0 * rho / max(r_p - rho, 1e-300)
    m = np.sqrt(bx * bx + by * by + bz * bz)
    x = min(1.0, turn / max(m, 1e-300))
    cosang = abs(bx * ax + by * ay + bz * az) / max(m, 1e-300)
    limit = cos_a * np.sqrt(1.0 - x * x) - sin_a * x
    return (not near) and (m > turn) and (cosang < limit) and margin_ok and not (wide and x >= sin_a)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _candidates_tree(V, F, N, S, P, tol, order, starts, centre, radius, axis, spread, bvert,
                     bvstart, local, tight_radius, n_centre, n_radius, n_axis, n_spread,
                     n_first, roots, allowed, tight, perm, groups, cap, out_pair, out_face,
                     out_st, out_pos):
    """:func:`_candidates` over blocks of spatially close facets, skipping a block where the
    reflection law cannot hold there, and whole nodes of blocks (a tree over the blocks, each
    node a sphere and a normal cone holding its children's) where it cannot hold in any.

    ``tight``: a block is skipped where the legs' bisector stays, everywhere in the block's
    sphere (``tight_radius``: grown by the most the smooth surface lifts off its facets), farther
    from its normal cone than asin 1e-3 — the residual a bounce point must meet — with 1e-3 rad to
    spare: no bounce point it could hold survives :func:`specular_points`' test, so the same
    points come out as from :func:`_candidates` (their Newton steps may stop at another
    iteration: the same points to ~1e-12 m). Otherwise the loose test: the cone's half-angle
    plus a fixed 0.1 rad margin (the candidates themselves are kept, or refined off the mesh);
    its nodes skip only where it skips every block, so the candidates are those of the block
    test alone. The blocks not ``allowed`` are skipped.

    The pairs go in groups (``perm[groups[g]:groups[g + 1]]``, one source, receivers close
    together): the tree is walked once per group, P anywhere in the group's sphere, and each
    pair then tests the blocks the walk kept. In such a block each vertex's source leg and
    each facet's basis are found once per group, each vertex's residual once per pair
    (``bvert``: the blocks' vertices, ``local``: each facet's three, indexed into its
    block's), with the products of :func:`_candidates`. Nodes: ids from the number of blocks
    on, the children of node i are ``n_first[i] .. n_first[i + 1]`` (blocks or nodes),
    ``roots`` the top ones. Rows: (pair, facet, s, t, the facet's place in block order);
    returns their number (rows past ``cap`` are counted, not written)."""
    k = 0
    n_b = starts.shape[0] - 1
    n_n = n_centre.shape[0]
    margin = _TIGHT_MARGIN if tight else _LOOSE_MARGIN
    a = np.empty(n_b)
    for blk in range(n_b):
        a[blk] = spread[blk] + margin
    cos_a = np.cos(a)
    sin_a = np.sin(a)
    wide = a >= 0.5 * np.pi
    margin_ok = a < np.pi          # a cone of half-angle π or more holds every direction
    n_a = n_spread + (margin if tight else margin + 1e-9)
    b_cos = np.cos(a + 1e-9)           # a block as a node of the loose test
    b_sin = np.sin(a + 1e-9)
    n_cos = np.cos(n_a)
    n_sin = np.sin(n_a)
    # a node holds an allowed block (children come before their parents)
    n_ok = np.zeros(n_n, np.uint8)
    for i in range(n_n):
        for c in range(n_first[i], n_first[i + 1]):
            if (allowed[c] if c < n_b else n_ok[c - n_b]) != 0:
                n_ok[i] = 1
                break
    most = 0
    for blk in range(n_b):
        most = max(most, bvstart[blk + 1] - bvstart[blk])
    tang = np.empty((most, 3))
    stack = np.empty(64 * (roots.shape[0] + 16), np.int64)
    kept = np.empty(n_b, np.int64)
    ready = np.zeros(n_b, np.int64) - 1          # the group whose caches a block's slots hold
    slot_v = np.empty(n_b, np.int64)
    slot_f = np.empty(n_b, np.int64)
    es = np.empty((0, 3))
    basis = np.empty((0, 7))
    for g in range(groups.shape[0] - 1):
        g0, g1 = groups[g], groups[g + 1]
        Sg = S[perm[g0]]
        cx = cy = cz = 0.0
        for q in range(g0, g1):
            cx += P[perm[q], 0]
            cy += P[perm[q], 1]
            cz += P[perm[q], 2]
        n_g = g1 - g0
        Pg = np.array([cx / n_g, cy / n_g, cz / n_g])
        r_g = 0.0
        for q in range(g0, g1):
            dx, dy, dz = P[perm[q], 0] - Pg[0], P[perm[q], 1] - Pg[1], P[perm[q], 2] - Pg[2]
            r_g = max(r_g, np.sqrt(dx * dx + dy * dy + dz * dz))
        r_g = r_g * (1.0 + 1e-9) + 1e-12
        # the walk: the blocks that may hold a bounce point of some pair of the group
        n_kept = 0
        top = 0
        for i in range(roots.shape[0] - 1, -1, -1):
            stack[top] = roots[i]
            top += 1
        while top > 0:
            top -= 1
            node = stack[top]
            if node >= n_b:
                i = node - n_b
                if n_ok[i] == 0:
                    continue
                if tight:
                    skip = _skip_tight(Sg, Pg, n_centre[i, 0], n_centre[i, 1], n_centre[i, 2],
                                       n_radius[i], n_radius[i] + r_g, n_axis[i, 0],
                                       n_axis[i, 1], n_axis[i, 2], n_cos[i], n_sin[i])
                else:
                    skip = _skip_node_loose(Sg, Pg, n_centre[i, 0], n_centre[i, 1],
                                            n_centre[i, 2], n_radius[i], n_radius[i] + r_g,
                                            n_axis[i, 0], n_axis[i, 1], n_axis[i, 2],
                                            n_cos[i], n_sin[i])
                if not skip:
                    for c in range(n_first[i + 1] - 1, n_first[i] - 1, -1):
                        stack[top] = c
                        top += 1
            elif allowed[node] != 0:
                # the block itself, for any P of the group (a node of one block)
                if tight:
                    skip = _skip_tight(Sg, Pg, centre[node, 0], centre[node, 1],
                                       centre[node, 2], tight_radius[node],
                                       tight_radius[node] + r_g, axis[node, 0], axis[node, 1],
                                       axis[node, 2], cos_a[node], sin_a[node])
                else:
                    skip = _skip_node_loose(Sg, Pg, centre[node, 0], centre[node, 1],
                                            centre[node, 2], radius[node], radius[node] + r_g,
                                            axis[node, 0], axis[node, 1], axis[node, 2],
                                            b_cos[node], b_sin[node])
                if not skip:
                    kept[n_kept] = node
                    n_kept += 1
        # this group's caches: each kept block's source legs and facet bases, made on first use
        n_vs = 0
        n_fs = 0
        for ib in range(n_kept):
            blk = kept[ib]
            n_vs += bvstart[blk + 1] - bvstart[blk]
            n_fs += starts[blk + 1] - starts[blk]
        if es.shape[0] < n_vs:
            es = np.empty((n_vs, 3))
        if basis.shape[0] < n_fs:
            basis = np.empty((n_fs, 7))
        used_v = 0
        used_f = 0
        for q in range(g0, g1):
            j = perm[q]
            Pj = P[j]
            for ib in range(n_kept):
                blk = kept[ib]
                if tight:
                    skip = _skip_tight(Sg, Pj, centre[blk, 0], centre[blk, 1], centre[blk, 2],
                                       tight_radius[blk], tight_radius[blk], axis[blk, 0],
                                       axis[blk, 1], axis[blk, 2], cos_a[blk], sin_a[blk])
                else:
                    skip = _skip_block_loose(Sg, Pj, centre[blk, 0], centre[blk, 1],
                                             centre[blk, 2], radius[blk], axis[blk, 0],
                                             axis[blk, 1], axis[blk, 2], cos_a[blk], sin_a[blk],
                                             wide[blk], margin_ok[blk])
                if skip:
                    continue
                v0 = bvstart[blk]
                nv = bvstart[blk + 1] - v0
                f0 = starts[blk]
                nf = starts[blk + 1] - f0
                if ready[blk] != g:
                    ready[blk] = g
                    slot_v[blk] = used_v
                    slot_f[blk] = used_f
                    for u in range(nv):
                        w = bvert[v0 + u]
                        dx, dy, dz = V[w, 0] - Sg[0], V[w, 1] - Sg[1], V[w, 2] - Sg[2]
                        r = np.sqrt(dx * dx + dy * dy + dz * dz)
                        if r > 0.0:
                            es[used_v + u, 0] = dx / r
                            es[used_v + u, 1] = dy / r
                            es[used_v + u, 2] = dz / r
                        else:
                            es[used_v + u, 0] = es[used_v + u, 1] = es[used_v + u, 2] = 0.0
                    for u in range(nf):
                        f = order[f0 + u]
                        ok, u1x, u1y, u1z, u2x, u2y, u2z = _facet_basis(V, F[f, 0], F[f, 1], F[f, 2])
                        basis[used_f + u, 0] = 1.0 if ok else 0.0
                        basis[used_f + u, 1] = u1x
                        basis[used_f + u, 2] = u1y
                        basis[used_f + u, 3] = u1z
                        basis[used_f + u, 4] = u2x
                        basis[used_f + u, 5] = u2y
                        basis[used_f + u, 6] = u2z
                    used_v += nv
                    used_f += nf
                sv, sf = slot_v[blk], slot_f[blk]
                for u in range(nv):
                    w = bvert[v0 + u]
                    # the bisector as _residual sums it: 0, then the source's leg, then P's
                    bx = by = bz = 0.0
                    bx += es[sv + u, 0]
                    by += es[sv + u, 1]
                    bz += es[sv + u, 2]
                    dx, dy, dz = V[w, 0] - Pj[0], V[w, 1] - Pj[1], V[w, 2] - Pj[2]
                    r = np.sqrt(dx * dx + dy * dy + dz * dz)
                    if r > 0.0:
                        bx += dx / r
                        by += dy / r
                        bz += dz / r
                    bn = bx * N[w, 0] + by * N[w, 1] + bz * N[w, 2]
                    tang[u, 0] = bx - bn * N[w, 0]
                    tang[u, 1] = by - bn * N[w, 1]
                    tang[u, 2] = bz - bn * N[w, 2]
                for u in range(nf):
                    if basis[sf + u, 0] == 0.0:
                        continue
                    i = f0 + u
                    la, lb, lc = local[i, 0], local[i, 1], local[i, 2]
                    ok, s, t = _facet_solve(basis[sf + u, 1], basis[sf + u, 2], basis[sf + u, 3],
                                            basis[sf + u, 4], basis[sf + u, 5], basis[sf + u, 6],
                                            (tang[la, 0], tang[la, 1], tang[la, 2]),
                                            (tang[lb, 0], tang[lb, 1], tang[lb, 2]),
                                            (tang[lc, 0], tang[lc, 1], tang[lc, 2]), tol)
                    if ok:
                        if k < cap:
                            out_pos[k] = i
                        k = _keep(k, cap, j, order[i], s, t, out_pair, out_face, out_st)
    return k


@nb.njit(cache=True, nogil=True)
def _morton(q):
    """Morton (Z-curve) codes of points quantised to 10 bits per axis, q (n, 3) uint64."""
    code = np.zeros(q.shape[0], np.uint64)
    for i in range(q.shape[0]):
        c = np.uint64(0)
        for bit in range(10):
            for d in range(3):
                c |= ((q[i, d] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + d)
        code[i] = c
    return code


def _blocks(V, F, N, size: int = 16):
    """Facets in Morton (Z-curve) order of their centroids, cut into blocks of ``size``; each
    block's bounding sphere and its vertex normals' cone (axis, half-angle)."""
    # one scale for every axis: a thin dimension (a sea's heights) gets few bits, not the top one
    order = np.argsort(_morton(facet_cells(V, F)), kind="stable")
    starts = np.append(np.arange(0, len(F), size), len(F)).astype(np.int64)
    fv = np.ascontiguousarray(F[order].ravel(), np.int64)  # 3 vertices per facet, in order
    at = 3 * starts[:-1]
    counts = np.diff(3 * starts)
    pts, nrm = V[fv], N[fv]
    # the spheres and normal sums in one compiled pass, with numpy's order of additions
    centre, radius, axis, na = block_spheres(pts, nrm, 3 * starts)
    owner = np.repeat(np.arange(at.size), counts)
    cosv = np.clip(np.einsum("ij,ij->i", nrm, axis[owner]), -1.0, 1.0)
    spread = np.where(na > 0, np.arccos(np.minimum.reduceat(cosv, at)), np.pi)
    # each block's distinct vertices, and each facet's three as indices into its block's list
    bvert, bvstart, local = block_vertices(fv, 3 * starts)
    # the tight test's spheres: the smooth surface lifts a facet's point by at most half its
    # longest edge times the sine between a vertex normal and the facet's (Phong, α = ½)
    sag = facet_sag(V, F, N, order)
    tight_radius = (radius + np.maximum.reduceat(sag, starts[:-1])) * (1 + 1e-9) + 1e-12
    return (order.astype(np.int64), starts, centre, radius, axis, spread, bvert, bvstart,
            np.ascontiguousarray(local), tight_radius, *_tree(centre, tight_radius, axis, spread))


def _tree(centre, radius, axis, spread, fan: int = 8):
    """Nodes over the blocks (consecutive in Morton order, ``fan`` to a node, level by level
    until at most ``fan`` are left): each node's sphere holds its children's spheres and its
    normal cone their cones. Returns (centre, radius, axis, spread, first, roots): node i's
    children are the ids ``first[i] .. first[i + 1]`` (ids below the number of blocks are
    blocks, node i is id n_blocks + i), ``roots`` the ids of the top level."""
    n_b = centre.shape[0]
    cen, rad, ax, spr, first = [], [], [], [], []
    ids = np.arange(n_b, dtype=np.int64)          # the current level's ids
    lc, lr, la, ls = centre, radius, axis, spread
    while ids.size > fan:
        at = np.arange(0, ids.size, fan)
        cnt = np.diff(np.append(at, ids.size))
        owner = np.repeat(np.arange(at.size), cnt)
        c = np.add.reduceat(lc, at, axis=0) / cnt[:, None]
        r = np.maximum.reduceat(np.linalg.norm(lc - c[owner], axis=1) + lr, at) * (1 + 1e-9)
        s = np.add.reduceat(la, at, axis=0)
        ns = np.linalg.norm(s, axis=1)
        a = np.where(ns[:, None] > 0, s / np.where(ns > 0, ns, 1.0)[:, None], [0.0, 0.0, 1.0])
        turn = np.arccos(np.clip(np.einsum("ij,ij->i", la, a[owner]), -1.0, 1.0))
        sp = np.minimum(np.maximum.reduceat(turn + ls, at) * (1 + 1e-9) + 1e-12, np.pi)
        first.append(ids[at])
        cen.append(c), rad.append(r), ax.append(a), spr.append(sp)
        ids = n_b + sum(len(x) for x in cen[:-1]) + np.arange(at.size, dtype=np.int64)
        lc, lr, la, ls = c, r, a, sp
    if not cen:
        z = np.zeros((0, 3))
        return z, np.zeros(0), z.copy(), np.zeros(0), np.zeros(1, np.int64), ids
    # the last level's children end where its own ids begin
    first = np.concatenate(first + [ids[:1]]).astype(np.int64)
    return (np.concatenate(cen), np.concatenate(rad), np.ascontiguousarray(np.concatenate(ax)),
            np.concatenate(spr), first, ids)


#: the last grown blocks (the blocks they grew, a digest of the field at the vertices, the
#: grown blocks): a ping searches one sea from the transmitter and from the receiver
_FIELD_CACHE: list = []


def _field_blocks_of(V, F, blocks, field_normals, off_m, slope, curvature_per_m, up):
    """The blocks grown by :func:`acoustics.paths.specular_field.height_field_blocks` (and their
    tree), kept for the last two (blocks, field) it was asked for
    (arguments as ``height_field_blocks``'; ``up``: the field's z axis in the mesh's frame).

    Returns
    -------
    tuple
        The grown blocks, for :func:`candidate_facets`."""
    n_field = np.ascontiguousarray(field_normals, dtype=float)
    up = np.asarray(up, float)
    key = (hash(n_field.tobytes()), n_field.shape, float(off_m), float(slope),
           float(curvature_per_m), tuple(up.tolist()))
    with _BLOCK_LOCK:
        for entry in _FIELD_CACHE:
            if entry[0] is blocks and entry[1] == key and np.array_equal(entry[2], n_field):
                return entry[3]
    tight_radius, spread = height_field_blocks(V, F, blocks, n_field, off_m, slope,
                                               curvature_per_m, up)
    grown = (*blocks[:5], spread, *blocks[6:9], tight_radius,
             *_tree(blocks[2], tight_radius, blocks[4], spread))
    with _BLOCK_LOCK:
        _FIELD_CACHE.insert(0, (blocks, key, n_field, grown))
        del _FIELD_CACHE[2:]
    return grown


#: the blocks of the last few meshes searched, keyed by where their arrays live, their shapes
#: and a sample of their values (the arrays are held, so that the memory stays theirs: a key
#: cannot be taken over by another array, only by one changed in place, which abacus' meshes
#: never are); a moving sea's mesh is new every ping and simply misses. Shared by the threads
#: of one process (two simulations at once), hence the lock.
_BLOCK_CACHE: list = []
_BLOCK_LOCK = threading.Lock()


def _blocks_of(V, F, normals):
    """:func:`_blocks` and the unit normals, cached (``normals``: the caller's array, before
    it was normalised). Returns (blocks, unit normals)."""
    key = tuple((a.__array_interface__["data"][0], a.shape, float(a.reshape(-1)[::211].sum()))
                for a in (V, F, normals))
    with _BLOCK_LOCK:
        for i, entry in enumerate(_BLOCK_CACHE):
            if entry[0] == key:
                # most recently used first: a still floor is not pushed out by each ping's new sea
                _BLOCK_CACHE.insert(0, _BLOCK_CACHE.pop(i))
                return entry[2], entry[3]
    N = np.ascontiguousarray(_unit(normals))
    blocks = _blocks(V, F, N)
    with _BLOCK_LOCK:
        _BLOCK_CACHE.insert(0, (key, (V, F, normals), blocks, N))
        del _BLOCK_CACHE[4:]
    return blocks, N


def search_blocks(vertices, faces, normals):
    """The blocks of facets (and their tree) :func:`candidate_facets` culls with, and the unit
    normals they were made from, for a caller that keeps them with its mesh (its ``blocks``
    argument).

    Parameters
    ----------
    vertices : array_like, shape (n_v, 3)
        Mesh vertices (m).
    faces : array_like of int, shape (n_f, 3)
    normals : array_like, shape (n_v, 3)
        Vertex normals (any length).

    Returns
    -------
    (tuple, ndarray of shape (n_v, 3))
        The blocks (opaque to callers) and the unit normals.
    """
    N = np.ascontiguousarray(_unit(np.asarray(normals, float)))
    return _blocks(np.ascontiguousarray(np.asarray(vertices, float)),
                   np.ascontiguousarray(np.asarray(faces, np.int64)), N), N


def _pair_groups(S, P, size: int = 32):
    """The pairs in groups for :func:`_candidates_tree`: one source per group and receivers
    close together (runs of ``size`` in Morton order of the receivers). Returns (perm, groups):
    group g is ``perm[groups[g]:groups[g + 1]]``. The groups' size changes only the time (each
    pair is tested alone after its group's walk): 32 walks the tree half as often as 16 for
    about as many blocks per pair (the hard survey's searches ~5 % faster)."""
    if (S == S[0]).all():                   # the usual case: one phase centre
        sid = np.zeros(S.shape[0], np.int64)
    else:
        _, sid = np.unique(S, axis=0, return_inverse=True)
        sid = sid.reshape(-1)
    lo, hi = P.min(axis=0), P.max(axis=0)
    q = ((P - lo) / max(float((hi - lo).max()), 1e-300) * 1023).astype(np.uint64)
    perm = np.lexsort((_morton(q), sid)).astype(np.int64)
    # a group never spans two sources
    run = np.flatnonzero(np.diff(sid[perm])) + 1
    edges = [np.arange(a, b, size) for a, b in zip(np.r_[0, run], np.r_[run, P.shape[0]])]
    return perm, np.append(np.concatenate(edges), P.shape[0]).astype(np.int64)


_POOL: list = []


def _pool():
    """Two worker threads for the search, started once (None on one core)."""
    import os
    from concurrent.futures import ThreadPoolExecutor
    if min(2, os.cpu_count() or 1) < 2:
        return None
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(2, thread_name_prefix="abacus-specular"))
    return _POOL[0]


def _search_split(V, F, N, S, P, tol, blocks, cap, allowed, tight):
    """The blocked search (:func:`_candidates_tree`) with the pairs' groups split across two
    threads (the kernel releases the GIL); the rows come back in the order of
    :func:`_candidates` (pair, then facet in block order), whatever the split."""
    perm, groups = _pair_groups(S, P)

    def run(g0, g1):
        c = max(256, cap * (groups[g1] - groups[g0]) // max(S.shape[0], 1))
        while True:
            pair = np.empty(c, np.int64)
            face = np.empty(c, np.int64)
            st = np.empty((c, 2))
            pos = np.empty(c, np.int64)
            k = _candidates_tree(V, F, N, S, P, tol, *blocks, allowed, tight, perm,
                                 groups[g0:g1 + 1], c, pair, face, st, pos)
            if k <= c:
                return pair[:k], face[:k], st[:k], pos[:k]
            c = k

    n_g = groups.size - 1
    pool = _pool() if S.shape[0] >= 64 and n_g >= 2 else None
    if pool is None:
        out = [run(0, n_g)]
    else:
        # four runs of groups with about as many pairs each, taken by the two threads as they
        # come free: on a shared machine one thread may stall, and the other goes on
        parts = min(4, n_g)
        cuts = np.unique(np.clip(np.searchsorted(groups, np.arange(parts + 1) * S.shape[0] // parts),
                                 0, n_g))
        out = list(pool.map(lambda ab: run(*ab), zip(cuts[:-1], cuts[1:])))
    pair, face, st, pos = (np.concatenate(col) for col in zip(*out))
    o = np.lexsort((pos, pair))
    return pair[o], face[o], st[o]
