"""Per-facet parts of the specular search's blocks (acoustics/paths/specular_search.py): each
block's distinct vertices, and how far the smooth surface lifts a facet off its plane. Compiled
loops without allocation per facet: a moving sea's blocks are made every ping.
"""
from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["block_spheres", "block_vertices", "facet_cells", "facet_sag"]


@nb.njit(cache=True, nogil=True)
def block_vertices(fv, at):
    """Each block's distinct vertices, and each facet's three as indices into its block's list.

    A block holds a few dozen vertices: a small sort each, not one sort of them all.

    Parameters
    ----------
    fv : ndarray of int64, shape (3 n_f,)
        The facets' vertices, three per facet, in block order.
    at : ndarray of int64, shape (n_blocks + 1,)
        Block b's vertices are ``fv[at[b]:at[b + 1]]``.

    Returns
    -------
    bvert : ndarray of int64, shape (k,)
        Each block's distinct vertices in ascending order, block after block.
    bvstart : ndarray of int64, shape (n_blocks + 1,)
        Where each block's list starts in ``bvert``.
    local : ndarray of int64, shape (n_f, 3)
        Each facet's vertices as places in its block's list.
    """
    n_b = at.shape[0] - 1
    bvert = np.empty(fv.shape[0], np.int64)
    bvstart = np.empty(n_b + 1, np.int64)
    local = np.empty(fv.shape[0], np.int64)
    n = 0
    for b in range(n_b):
        bvstart[b] = n
        srt = np.sort(fv[at[b]:at[b + 1]])
        for i in range(srt.shape[0]):
            if i == 0 or srt[i] != srt[i - 1]:
                bvert[n] = srt[i]
                n += 1
        m = n - bvstart[b]
        for i in range(at[b], at[b + 1]):
            lo, hi = 0, m                  # the vertex's place in its block's sorted list
            while lo < hi:
                mid = (lo + hi) // 2
                if bvert[bvstart[b] + mid] < fv[i]:
                    lo = mid + 1
                else:
                    hi = mid
            local[i] = lo
    bvstart[n_b] = n
    return bvert[:n].copy(), bvstart, local.reshape(-1, 3)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def facet_sag(V, F, N, order):
    """Per facet: the most the smooth surface lifts a point of it off its plane, half its
    longest edge times the largest sine between a vertex normal and the facet's normal
    (Phong, α = ½), plus 1e-6 of the edge (points found 1e-6 outside it).

    Parameters
    ----------
    V : ndarray, shape (n_v, 3)
        Vertices (m).
    F : ndarray of int64, shape (n_f, 3)
    N : ndarray, shape (n_v, 3)
        Unit vertex normals.
    order : ndarray of int64, shape (k,)
        The facets, in the order wanted.

    Returns
    -------
    ndarray, shape (k,)
        The lift (m).
    """
    out = np.empty(order.shape[0])
    for i in range(order.shape[0]):
        f = order[i]
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        # scalars, not small arrays: no allocation per facet (the moving sea's, every ping)
        e1x, e1y, e1z = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
        e2x, e2y, e2z = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
        e3x, e3y, e3z = V[c, 0] - V[b, 0], V[c, 1] - V[b, 1], V[c, 2] - V[b, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        nl = np.sqrt(nx * nx + ny * ny + nz * nz)
        edge = max(np.sqrt(e1x * e1x + e1y * e1y + e1z * e1z),
                   np.sqrt(e2x * e2x + e2y * e2y + e2z * e2z),
                   np.sqrt(e3x * e3x + e3y * e3y + e3z * e3z))
        worst = 0.0
        if nl > 0.0:
            for v in (a, b, c):
                cv = abs(N[v, 0] * nx + N[v, 1] * ny + N[v, 2] * nz) / nl
                worst = max(worst, np.sqrt(max(0.0, 1.0 - cv * cv)))
        else:
            worst = 1.0                  # a degenerate facet: any lift up to its size
        out[i] = 0.5 * edge * worst + 1e-6 * edge
    return out


@nb.njit(cache=True, nogil=True)
def facet_cells(V, F):
    """Each facet's centroid quantised to 10 bits per axis, one scale for every axis (a thin
    dimension, a sea's heights, gets few bits), for the facets' Morton order.

    Parameters
    ----------
    V : ndarray, shape (n_v, 3)
        Vertices (m).
    F : ndarray of int64, shape (n_f, 3)

    Returns
    -------
    ndarray of uint64, shape (n_f, 3)
    """
    n = F.shape[0]
    cen = np.empty((n, 3))
    for i in range(n):
        for j in range(3):
            cen[i, j] = (V[F[i, 0], j] + V[F[i, 1], j] + V[F[i, 2], j]) / 3.0
    lo = np.empty(3)
    hi = np.empty(3)
    for j in range(3):
        lo[j] = cen[0, j] if n else 0.0
        hi[j] = lo[j]
        for i in range(n):
            lo[j] = min(lo[j], cen[i, j])
            hi[j] = max(hi[j], cen[i, j])
    scale = max(max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]), 1e-300)
    q = np.empty((n, 3), np.uint64)
    for i in range(n):
        for j in range(3):
            q[i, j] = np.uint64((cen[i, j] - lo[j]) / scale * 1023)
    return q



@nb.njit(cache=True, nogil=True)
def _pairwise(a, lo, n, col):
    """numpy's pairwise sum of ``a[lo:lo + n, col]`` (its order of additions, so the same
    bits as numpy's reductions: eight running sums below 128 terms, halves above)."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i, col]
        return res
    if n <= 128:
        r = np.empty(8)
        for j in range(8):
            r[j] = a[lo + j, col]
        i = 8
        while i < n - (n % 8):
            for j in range(8):
                r[j] += a[lo + i + j, col]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        while i < n:
            res += a[lo + i, col]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise(a, lo, n2, col) + _pairwise(a, lo + n2, n - n2, col)


@nb.njit(cache=True, nogil=True)
def block_spheres(pts, nrm, at):
    """Each block's sphere and the sum of its normals, with numpy's order of additions (a
    segment's first row plus the pairwise sum of the rest, as ``np.add.reduceat``; three
    components summed in order): the same bits as the numpy expressions it replaces.

    Parameters
    ----------
    pts, nrm : ndarray, shape (m, 3)
        The blocks' facets' vertices (m) and their unit normals, three rows per facet, in
        block order.
    at : ndarray of int64, shape (n_blocks + 1,)
        Block b's rows are ``at[b]:at[b + 1]``.

    Returns
    -------
    centre : ndarray, shape (n_blocks, 3)
        The mean of its rows (m).
    radius : ndarray, shape (n_blocks,)
        The farthest row from the centre (m).
    axis : ndarray, shape (n_blocks, 3)
        The unit sum of its normals (+z where the sum vanishes).
    norm : ndarray, shape (n_blocks,)
        The length of that sum.
    """
    n_b = at.shape[0] - 1
    centre = np.empty((n_b, 3))
    radius = np.empty(n_b)
    axis = np.empty((n_b, 3))
    norm = np.empty(n_b)
    for b in range(n_b):
        lo, hi = at[b], at[b + 1]
        cnt = float(hi - lo)
        s = np.empty(3)
        for c in range(3):
            centre[b, c] = (pts[lo, c] + _pairwise(pts, lo + 1, hi - lo - 1, c)) / cnt
            s[c] = nrm[lo, c] + _pairwise(nrm, lo + 1, hi - lo - 1, c)
        far = -np.inf
        for r in range(lo, hi):
            d0 = pts[r, 0] - centre[b, 0]
            d1 = pts[r, 1] - centre[b, 1]
            d2 = pts[r, 2] - centre[b, 2]
            far = max(far, d0 ** 2 + d1 ** 2 + d2 ** 2)
        radius[b] = np.sqrt(far)
        na = np.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
        norm[b] = na
        for c in range(3):
            axis[b, c] = s[c] / na if na > 0 else (1.0 if c == 2 else 0.0)
    return centre, radius, axis, norm
