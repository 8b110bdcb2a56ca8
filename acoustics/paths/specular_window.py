"""The specular search's window (``effects.specular.beam_level_db``): the blocks of facets, and
near the window's origin the facets themselves, that reach into an angular window seen from its
origin (a transmitter's fan, an element's); :func:`acoustics.paths.specular_search.candidate_facets`
searches only those.
"""
from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["window_blocks"]


#: a block seen under more than this half-angle (rad) from a window's origin (one near it: a
#: sea above the sonar) is windowed facet by facet: its sphere alone would let facets far
#: outside the window in
_NEAR_BLOCK_RAD = 0.05


@nb.njit(cache=True, nogil=True)
def _facet_spheres(V, F, f):
    """Facets ``f``' spheres: centroid (k, 3) and farthest vertex from it (k,) (m)."""
    cen = np.empty((f.shape[0], 3))
    rad = np.empty(f.shape[0])
    for i in range(f.shape[0]):
        for j in range(3):
            cen[i, j] = (V[F[f[i], 0], j] + V[F[f[i], 1], j] + V[F[f[i], 2], j]) / 3.0
        r2 = 0.0
        for q in range(3):
            v = F[f[i], q]
            d0, d1, d2 = V[v, 0] - cen[i, 0], V[v, 1] - cen[i, 1], V[v, 2] - cen[i, 2]
            r2 = max(r2, d0 * d0 + d1 * d1 + d2 * d2)
        rad[i] = np.sqrt(r2)
    return cen, rad


def _inside_window(c, radius, az_lo, az_hi, el_lo, el_hi):
    """Whether spheres (centres ``c`` (n, 3) in the window's axes, ``radius`` (n,)) reach into
    the angular window; and each one's angular radius (π for one holding the origin)."""
    r = np.linalg.norm(c, axis=1)
    pad = np.arcsin(np.clip(radius / np.maximum(r, 1e-300), 0.0, 1.0))
    pad = np.where(r > radius, pad, np.pi)          # the origin inside the sphere: keep
    el = np.arcsin(np.clip(c[:, 1] / np.maximum(r, 1e-300), -1.0, 1.0))
    az = np.arctan2(c[:, 0], c[:, 2])
    inside = ((el >= el_lo - pad) & (el <= el_hi + pad) & (az >= az_lo - pad)
              & (az <= az_hi + pad))
    return inside, pad


def window_blocks(blocks, window, vertices=None, faces=None):
    """The blocks of facets whose bounding sphere, seen from the window's origin, reaches into
    its angular window (az = atan2(x, z), el = asin(y/r) in the window's axes).

    With the mesh (``vertices``, ``faces``), a block seen under more than
    ``_NEAR_BLOCK_RAD`` is taken facet by facet (each facet's own sphere: its centroid, its
    farthest vertex): such a block is kept when a facet of it reaches into the window
    (``effects.specular.near_facets``).

    Parameters
    ----------
    blocks : tuple
        :func:`acoustics.paths.specular_search.search_blocks`' blocks.
    window : (ndarray (3,), ndarray (3, 3), (float, float, float, float))
        Origin (m), rotation whose columns are the window's axes, (az_lo, az_hi, el_lo, el_hi)
        (rad).
    vertices : ndarray, shape (n_v, 3), optional
        Mesh vertices (m).
    faces : ndarray of int64, shape (n_f, 3), optional

    Returns
    -------
    allowed : ndarray of uint8, shape (n_blocks,)
        1 for a block to search.
    facet_ok : ndarray of bool, shape (n_f,), or None
        False for the facets of the kept near blocks that do not reach into the window
        (None without the mesh, or when no facet was left out).
    """
    origin, rotation, (az_lo, az_hi, el_lo, el_hi) = window
    origin = np.asarray(origin, float)
    rotation = np.asarray(rotation, float)
    centre, radius = blocks[2], blocks[3]
    c = (centre - origin) @ rotation
    inside, pad = _inside_window(c, radius, az_lo, az_hi, el_lo, el_hi)
    if vertices is None:
        return inside.astype(np.uint8), None
    near = np.flatnonzero(inside & (pad > _NEAR_BLOCK_RAD))
    if near.size == 0:
        return inside.astype(np.uint8), None
    order, starts = blocks[0], blocks[1]
    cnt = starts[near + 1] - starts[near]
    # the near blocks' facets, in block order
    pos = np.repeat(starts[near] - np.cumsum(cnt) + cnt, cnt) + np.arange(int(cnt.sum()))
    f = order[pos]
    cen, rad = _facet_spheres(vertices, faces, f)
    ok, _ = _inside_window((cen - origin) @ rotation, rad, az_lo, az_hi, el_lo, el_hi)
    if ok.all():
        return inside.astype(np.uint8), None
    facet_ok = np.ones(faces.shape[0], bool)
    facet_ok[f[~ok]] = False
    # a near block none of whose facets reaches in is not searched
    any_ok = np.maximum.reduceat(ok.astype(np.uint8), np.cumsum(cnt) - cnt) > 0
    inside[near[~any_ok]] = False
    return inside.astype(np.uint8), facet_ok
