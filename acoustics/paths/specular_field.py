"""The tight block bound of the specular search (acoustics/paths/specular_search.py) for
bounce points refined on an exact height field (a moving sea): each block's sphere and normal
cone grown by how far a refined point may lie from its facet's candidate, bounded by the
field's curvature (docs/accuracy.md, "Specular search": the same paths as every facet).
"""
from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["height_field_blocks"]


#: how far (in units of the facet's own size, barycentric) a point refined on an exact height
#: field may lie outside its facet and be kept (``specular_points``' ``_inside_xy`` test)
_FIELD_REACH = 0.5


def height_field_blocks(V, F, blocks, field_normals, off_m: float, slope: float,
                        curvature_per_m: float, up=(0.0, 0.0, 1.0)):
    """The blocks of :func:`acoustics.paths.specular_search._blocks` with the tight test's spheres and normal cones grown to
    hold every point a candidate of theirs may be refined to on an exact height field.

    Such a point is kept only within its facet's (x, y) triangle (the field's frame) grown
    ``_FIELD_REACH`` = e beyond each edge (the triangle scaled by g = 1 + 3e about its
    centroid), on the field. With r the facet's largest centroid–vertex distance: its (x, y) is
    within (g + 1)·r of each vertex; the facet's plane over it lies in the grown triangle (its
    corners bound the distance to the block's centre); the field departs from that plane by at
    most ½·κ·Σ|λ|·((g + 1)·r)² (the plane interpolates the field at the vertices with
    barycentric weights λ, Σ|λ| ≤ 1 + 4e, whose first-order terms cancel; κ the Hessian's
    norm), plus Σ|λ| times the vertices' offset; its normal within κ·(g + 1)·r of the
    field's normal at a vertex (the unit normal turns by at most the gradient's change). The
    cone is taken about each block's own axis over the field's normals at its vertices, so the
    mesh's normals need not be the field's. A facet seen edge-on from the field's axis leaves
    its block unbounded (never skipped).

    Parameters
    ----------
    V : ndarray, shape (n_v, 3)
        Mesh vertices (m).
    F : ndarray of int64, shape (n_f, 3)
    blocks : tuple
        :func:`acoustics.paths.specular_search._blocks` of the mesh.
    field_normals : ndarray, shape (n_v, 3)
        The field's unit normals at the vertices (either sign), in the mesh's frame.
    off_m : float
        The most a vertex lies off the field (m).
    slope : float
        The field's largest |∇z| (a bound; unused by the bound, which needs the curvature only,
        kept for callers that state both).
    curvature_per_m : float
        The largest spectral norm of the field's Hessian (1/m, a bound).
    up : array_like, shape (3,)
        The field's z axis in the mesh's frame.

    Returns
    -------
    tight_radius : ndarray, shape (n_blocks,)
        The grown spheres' radii (m; inf: never skipped).
    spread : ndarray, shape (n_blocks,)
        The grown cones' half-angles (rad, at most π).
    """
    order, starts, centre, _, axis = blocks[:5]
    bvert, bvstart = blocks[6], blocks[7]
    tight_radius, spread = _field_reach(V, F, order, starts, centre, axis, bvert, bvstart,
                                        np.ascontiguousarray(field_normals, dtype=float),
                                        float(off_m), float(curvature_per_m),
                                        np.asarray(up, float), _FIELD_REACH)
    return tight_radius, spread


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _field_reach(V, F, order, starts, centre, axis, bvert, bvstart, NF, off, kappa, up, e):
    """:func:`height_field_blocks`' radii and half-angles, block by block."""
    n_b = starts.shape[0] - 1
    radius = np.empty(n_b)
    spread = np.empty(n_b)
    g = 1.0 + 3.0 * e
    lam = 1.0 + 4.0 * e                   # the most Σ|λ| over the grown triangle
    for blk in range(n_b):
        tr = 0.0
        tilt = 0.0
        flat = False
        for i in range(starts[blk], starts[blk + 1]):
            f = order[i]
            gx = gy = gz = 0.0
            for j in range(3):
                gx += V[F[f, j], 0] / 3.0
                gy += V[F[f, j], 1] / 3.0
                gz += V[F[f, j], 2] / 3.0
            r = 0.0
            for j in range(3):
                v = F[f, j]
                r = max(r, np.sqrt((V[v, 0] - gx) ** 2 + (V[v, 1] - gy) ** 2 + (V[v, 2] - gz) ** 2))
            corner = 0.0
            for j in range(3):
                v = F[f, j]
                cx = gx + g * (V[v, 0] - gx) - centre[blk, 0]
                cy = gy + g * (V[v, 1] - gy) - centre[blk, 1]
                cz = gz + g * (V[v, 2] - gz) - centre[blk, 2]
                corner = max(corner, np.sqrt(cx * cx + cy * cy + cz * cz))
            d = (g + 1.0) * r
            tr = max(tr, corner + 0.5 * kappa * lam * d * d + lam * off)
            tilt = max(tilt, kappa * d)
            # the facet's (x, y) triangle in the field's frame must not be degenerate
            a, b, c = F[f, 0], F[f, 1], F[f, 2]
            e1x, e1y, e1z = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
            e2x, e2y, e2z = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
            nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            nl = np.sqrt(nx * nx + ny * ny + nz * nz)
            if not abs(nx * up[0] + ny * up[1] + nz * up[2]) > 1e-6 * nl:
                flat = True
        cos_min = 1.0
        for u in range(bvstart[blk], bvstart[blk + 1]):
            w = bvert[u]
            cos_min = min(cos_min, abs(NF[w, 0] * axis[blk, 0] + NF[w, 1] * axis[blk, 1]
                                       + NF[w, 2] * axis[blk, 2]))
        cone = np.arccos(min(1.0, max(-1.0, cos_min)))
        if flat or not (tr < np.inf and cone + tilt < np.pi):
            radius[blk] = np.inf
            spread[blk] = np.pi
        else:
            radius[blk] = tr * (1.0 + 1e-9) + 1e-9
            spread[blk] = (cone + tilt) * (1.0 + 1e-9) + 1e-9
    return radius, spread
