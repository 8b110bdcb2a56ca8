"""A generated rough floor in tiles, built on demand and held in a run's cache of bounded memory.

A ``rough_floor`` of 10⁷ facets held whole costs ≈ 1.5 kB a facet (its mesh, the caster's copy,
Embree's BVH, the specular search's blocks): 15 GB. With ``effects.floor_tiles.enabled``,
the floor is never held whole. Its grid of vertices is cut into square tiles of
``tile_vertices`` per side (neighbours share their edge vertices, so every facet lies in exactly
one tile); a tile is generated, meshed and given its Embree scene when a ray batch, a segment or
a specular search first needs it, and kept in a :class:`TileCache` that evicts the least
recently used tile once the built tiles would exceed the setting. The floor itself
(:class:`FloorTiles`, held by the run's frozen set-up) is an immutable description and
generator; the cache is the run's (its ray caster's, built per run by the
:class:`~acoustics.simulation.setup.RunCache`), so a query never changes the set-up and two
runs from one set-up share no built tile. Which tiles a query needs is decided from each
tile's bounding box, known from a pass over the heights at set-up (heights only, a tile at a
time): a ray or segment needs the tiles its reach crosses; a specular search those whose
bounding sphere reaches into its fan (``effects.specular.beam_level_db``), else all.

**Deterministic per tile.** The height at grid vertex (i, j) depends on the scene's seed and
(i, j) only: white noise drawn in blocks of 256 x 256 vertices, each block from its own seed
(the scene's, the floor's, the block's indices), filtered by the Gaussian kernel
g(x) = exp(−x²/L²) (separable; the spectrum exp(−k²L²/4) of the whole-floor generator of
:mod:`acoustics.paths.meshes`), truncated at 4 L (|g| < 1.2·10⁻⁷), and scaled by
rms / Σg² (the field's RMS in expectation). Each tile is generated from the noise of its
vertices and a halo of the kernel's width, so the tiled floor equals the whole floor made by
the same generator, vertex for vertex, bit for bit (tests/test_floor_tiles.py); vertex
normals are taken over the tile and a one-vertex halo, so they too equal the whole mesh's.
The realisation differs from the untiled floor's FFT generator (same spectrum and RMS
in expectation, not the same draw; the FFT's field is periodic, this one is not).
"""
from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numba as nb
import numpy as np

from acoustics.seeds import ping_rng

__all__ = ["FloorTiles", "Tile", "TileCache", "TileMemoryError", "tile_bytes", "is_tiled"]

#: most vertices of a tiled floor (its set-up pass over the heights takes ≈ 1 s per 10⁶)
MAX_TILED_VERTICES = 10**8
#: noise is drawn in blocks of this many vertices a side, each from its own seed
_NOISE_BLOCK = 256
#: the kernel is cut at this many correlation lengths
_KERNEL_REACH = 4.0
#: the "ping" of the noise seeds (a floor is the same for every ping)
_FLOOR_PING = 2**31 - 3
#: bytes a facet of a built tile holds: its vertices and vertex normals (float64, float32 for
#: Embree), faces (int64, int32 for Embree), face planes and Embree's BVH (166 B measured: RSS
#: of 12 queried tiles of 131k facets), and the specular search's blocks of facets and their
#: tree (275 B measured), kept with the tile
_FACET_BYTES = 170.0 + 280.0


class TileMemoryError(ValueError):
    """The memory setting cannot hold one tile; the message names the key and what fits."""


def is_tiled(mesh) -> bool:
    """Whether a SceneMesh's ``mesh`` is a :class:`FloorTiles` (not a trimesh)."""
    return bool(getattr(mesh, "tiled", False))


def tile_bytes(tile_vertices: int) -> float:
    """Memory (bytes) of one built tile of ``tile_vertices`` a side."""
    return 2.0 * (tile_vertices - 1) ** 2 * _FACET_BYTES


def _kernel(resolution_m: float, correlation_m: float) -> np.ndarray:
    half = int(math.ceil(_KERNEL_REACH * correlation_m / resolution_m))
    x = np.arange(-half, half + 1) * resolution_m
    return np.exp(-(x / correlation_m) ** 2)


def _grid_faces(nx: int, ny: int) -> np.ndarray:
    """Faces of an nx x ny vertex grid, row-major (the order of meshes._grid_mesh)."""
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    b, c, d = a + 1, a + nx, a + nx + 1
    return np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])


@nb.njit(cache=True, nogil=True)
def _rays_in_boxes(o, u, reach, lo, hi, pad, out_count, out_idx, cap):
    """Slab test of every ray (origin o, unit direction u, length reach) against every box
    (lo, hi, padded by pad); for each box the rays that enter it, as CSR rows (counts, then
    indices). Returns how many indices there were (> cap: call again with more room)."""
    n_box = lo.shape[0]
    k = 0
    for b in range(n_box):
        cnt = 0
        for i in range(o.shape[0]):
            t0, t1 = 0.0, reach[i]
            ok = True
            for a in range(3):
                l_a, h_a = lo[b, a] - pad, hi[b, a] + pad
                if u[i, a] != 0.0:
                    inv = 1.0 / u[i, a]
                    ta, tb = (l_a - o[i, a]) * inv, (h_a - o[i, a]) * inv
                    if ta > tb:
                        ta, tb = tb, ta
                    if ta > t0:
                        t0 = ta
                    if tb < t1:
                        t1 = tb
                    if t0 > t1:
                        ok = False
                        break
                elif o[i, a] < l_a or o[i, a] > h_a:
                    ok = False
                    break
            if ok:
                if k < cap:
                    out_idx[k] = i
                k += 1
                cnt += 1
        out_count[b] = cnt
    return k


def face_planes(vertices, faces) -> np.ndarray:
    """Rows (unit face normal, n·v0), shape (n_f, 4), of a mesh's facets (the float64 planes
    hits are refined on, as acoustics/paths/raycast.py's RayCaster makes them)."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    n = n / np.where(norm > 0, norm, 1.0)[:, None]
    out = np.empty((f.shape[0], 4))
    out[:, :3] = n
    out[:, 3] = np.einsum("ij,ij->i", n, tri[:, 0])
    return out


@dataclass(eq=False)
class Tile:
    """One built tile: its mesh in the sonar frame and what queries need."""

    index: int
    vertices: np.ndarray
    """(n_v, 3) float64, m."""
    faces: np.ndarray
    """(n_f, 3) int64, into the tile's vertices."""
    normals: np.ndarray
    """(n_v, 3) unit vertex normals (equal to the whole floor's)."""
    face_plane: np.ndarray
    """(n_f, 4): unit face normal, n·v0."""
    face_start: int
    """The tile's first facet in the floor's numbering."""
    embree: object
    """Its Embree scene."""
    blocks: object = None
    """Its blocks of facets for the specular search (made at its first search)."""

    @property
    def nbytes(self) -> float:
        return tile_bytes_of(self.faces.shape[0])


def tile_bytes_of(n_faces: int) -> float:
    """Memory (bytes) a built tile of ``n_faces`` facets holds: mesh, normals, face planes,
    Embree scene and search blocks, at the measured bytes a facet.

    Parameters
    ----------
    n_faces : int

    Returns
    -------
    float
    """
    return float(n_faces) * _FACET_BYTES


class FloorTiles:
    """A ``rough_floor`` in tiles, in the sonar frame of the scene's build pose.

    Parameters
    ----------
    spec : RoughFloorShape
    seed : int
        The scene's seed.
    placement : ndarray, shape (4, 4)
        The floor's world frame (after the shape's transform) into the sonar frame.
    memory_mb : float
        Most memory (MB) the built tiles hold at once.
    tile_vertices : int
        Vertices a tile side.
    key : str
        The floor's key, for messages.
    robust : bool
        Embree's robust traversal.

    Raises
    ------
    TileMemoryError
        ``memory_mb`` cannot hold one tile.
    """

    #: what the ray caster asks of a mesh to treat it as tiles
    tiled = True

    def __init__(self, spec, seed: int, placement, *, memory_mb: float, tile_vertices: int = 513,
                 key: str = "boundaries[?]", robust: bool = True):
        self.spec = spec
        self.seed_total = int(seed) + int(spec.seed)
        self.placement = np.asarray(placement, float)
        self.memory_bytes = float(memory_mb) * 1e6
        self.robust = robust
        res = spec.resolution_m
        self.nx = int(np.ceil(spec.size_m[0] / res)) + 1
        self.ny = int(np.ceil(spec.size_m[1] / res)) + 1
        self.x = spec.center_m[0] + np.linspace(-spec.size_m[0] / 2, spec.size_m[0] / 2, self.nx)
        self.y = spec.center_m[1] + np.linspace(-spec.size_m[1] / 2, spec.size_m[1] / 2, self.ny)
        if self.nx * self.ny > MAX_TILED_VERTICES:
            raise TileMemoryError(f"{key}: a rough_floor of {self.nx} x {self.ny} vertices is too fine "
                                  f"even in tiles (limit {MAX_TILED_VERTICES:.0e} vertices): raise "
                                  f"resolution_m or shrink size_m")
        t = int(tile_vertices)
        self.tile_vertices = t
        # vertex ranges of the tiles along each axis (neighbours share an edge)
        self._ix = [(a, min(a + t, self.nx)) for a in range(0, self.nx - 1, t - 1)]
        self._iy = [(a, min(a + t, self.ny)) for a in range(0, self.ny - 1, t - 1)]
        self.tiles_x, self.tiles_y = len(self._ix), len(self._iy)
        self.n_tiles = self.tiles_x * self.tiles_y
        counts = np.array([2 * (i1 - i0 - 1) * (j1 - j0 - 1) for j0, j1 in self._iy
                           for i0, i1 in self._ix], np.int64)
        self.face_start = np.concatenate([[0], np.cumsum(counts)])
        self.n_faces = int(self.face_start[-1])
        least = tile_bytes_of(int(counts.max()))
        if least > self.memory_bytes:
            raise TileMemoryError(
                f"effects.floor_tiles.memory_mb = {memory_mb:g} cannot hold one tile of {key} "
                f"(≈ {least / 1e6:.3g} MB at tile_vertices {t}): raise memory_mb to at least "
                f"{least / 1e6:.3g} or lower effects.floor_tiles.tile_vertices")
        self._kernel = _kernel(res, spec.correlation_length_m) if spec.rms_height_m > 0 else None
        # bounding boxes (sonar frame) from a pass over the heights, a tile at a time
        self.box_lo = np.empty((self.n_tiles, 3))
        self.box_hi = np.empty((self.n_tiles, 3))
        for k in range(self.n_tiles):
            v = self._vertices(*self._window(k))
            self.box_lo[k], self.box_hi[k] = v.min(axis=0), v.max(axis=0)
        self.extent_m = float(max(np.abs(self.box_lo).max(), np.abs(self.box_hi).max()))
        self.centre = (self.box_lo + self.box_hi) / 2
        self.radius = np.linalg.norm(self.box_hi - self.box_lo, axis=1) / 2

    # ------------------------------------------------------------- generation
    def _window(self, k: int):
        """(i0, i1, j0, j1): the vertex ranges of tile k."""
        ty, tx = divmod(int(k), self.tiles_x)
        return (*self._ix[tx], *self._iy[ty])

    def _noise(self, i0, i1, j0, j1) -> np.ndarray:
        """White noise at vertices [j0:j1, i0:i1] (any integers), the same wherever asked."""
        b = _NOISE_BLOCK
        out = np.empty((j1 - j0, i1 - i0))
        for bj in range(j0 // b, (j1 - 1) // b + 1):
            for bi in range(i0 // b, (i1 - 1) // b + 1):
                group = ((bj + 2**20) << 22) | (bi + 2**20)
                block = ping_rng(self.seed_total, _FLOOR_PING, "reverberation", group).standard_normal((b, b))
                ja, jb = max(j0, bj * b), min(j1, (bj + 1) * b)
                ia, ib = max(i0, bi * b), min(i1, (bi + 1) * b)
                out[ja - j0:jb - j0, ia - i0:ib - i0] = block[ja - bj * b:jb - bj * b, ia - bi * b:ib - bi * b]
        return out

    def heights(self, i0, i1, j0, j1) -> np.ndarray:
        """Roughness h (m) at vertices [j0:j1, i0:i1] (within the grid), shape (j1-j0, i1-i0)."""
        if self._kernel is None:
            return np.zeros((j1 - j0, i1 - i0))
        from scipy.ndimage import correlate1d
        g = self._kernel
        half = g.size // 2
        w = self._noise(i0 - half, i1 + half, j0 - half, j1 + half)
        # each output is a fixed sum over its own neighbourhood: the same bits in any window
        w = correlate1d(w, g, axis=1, mode="constant")[:, half:half + (i1 - i0)]
        h = correlate1d(w, g, axis=0, mode="constant")[half:half + (j1 - j0)]
        return h * (self.spec.rms_height_m / float(np.sum(g * g)))

    def _vertices(self, i0, i1, j0, j1) -> np.ndarray:
        """Vertices (sonar frame) of the grid window, row-major, shape (n, 3)."""
        s = self.spec
        x, y = self.x[i0:i1], self.y[j0:j1]
        z = (s.depth_m + s.slope[0] * (x[None, :] - s.center_m[0])
             + s.slope[1] * (y[:, None] - s.center_m[1]) + self.heights(i0, i1, j0, j1))
        xx, yy = np.meshgrid(x, y)
        p = self.placement
        # elementwise (not a matrix product, whose rounding may depend on the batch): the same
        # bits for a vertex in any window
        xx, yy, z = xx.ravel(), yy.ravel(), z.ravel()
        return np.column_stack([p[r, 0] * xx + p[r, 1] * yy + p[r, 2] * z + p[r, 3] for r in range(3)])

    def whole(self):
        """(vertices, faces) of the whole floor by the same generator: the reference a tiled
        floor equals (tests, small floors only)."""
        return self._vertices(0, self.nx, 0, self.ny), _grid_faces(self.nx, self.ny)

    def build(self, k: int) -> Tile:
        """Tile k, generated, meshed and given its Embree scene (the floor is not changed: a
        :class:`TileCache` keeps what it builds)."""
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        from acoustics.paths.specular import vertex_normals
        i0, i1, j0, j1 = self._window(k)
        # one vertex of halo on each side that has a neighbour: vertex normals as the whole mesh's
        a0, a1 = max(i0 - 1, 0), min(i1 + 1, self.nx)
        b0, b1 = max(j0 - 1, 0), min(j1 + 1, self.ny)
        vh = self._vertices(a0, a1, b0, b1)
        nh = vertex_normals(vh, _grid_faces(a1 - a0, b1 - b0))
        keep = (np.arange(b0, b1)[:, None] >= j0) & (np.arange(b0, b1)[:, None] < j1) \
            & (np.arange(a0, a1)[None, :] >= i0) & (np.arange(a0, a1)[None, :] < i1)
        keep = keep.ravel()
        v = np.ascontiguousarray(vh[keep])
        n = np.ascontiguousarray(nh[keep])
        f = _grid_faces(i1 - i0, j1 - j0)
        embree = rtcore_scene.EmbreeScene(robust=self.robust)
        TriangleMesh(scene=embree, vertices=v.astype(np.float32), indices=f.astype(np.int32))
        return Tile(int(k), v, f, n, face_planes(v, f), int(self.face_start[k]), embree)

    # ---------------------------------------------------------------- queries
    def rays_per_tile(self, origins, directions, reach, pad: float):
        """[(tile, ray indices)] of the tiles each ray (unit directions, lengths ``reach``, inf
        for unbounded) may meet, boxes padded by ``pad`` (m); tiles in index order
        (:meth:`TileCache.rays_per_tile` visits them in the cache's order)."""
        o = np.ascontiguousarray(origins, float)
        u = np.ascontiguousarray(directions, float)
        r = np.ascontiguousarray(np.broadcast_to(np.asarray(reach, float), (o.shape[0],)))
        counts = np.zeros(self.n_tiles, np.int64)
        cap = max(1024, 2 * o.shape[0])
        while True:
            idx = np.empty(cap, np.int64)
            k = _rays_in_boxes(o, u, r, self.box_lo, self.box_hi, float(pad), counts, idx, cap)
            if k <= cap:
                break
            cap = k
        edges = np.concatenate([[0], np.cumsum(counts)])
        return [(int(t), idx[edges[t]:edges[t + 1]]) for t in np.flatnonzero(counts)]

    def tiles_in_window(self, window) -> np.ndarray:
        """Tiles whose bounding sphere reaches into an angular window (origin (3,), rotation
        (3, 3), (az_lo, az_hi, el_lo, el_hi) rad, az = atan2(x, z), el = asin(y / r) in the
        rotation's axes); every tile without one."""
        if window is None:
            return np.arange(self.n_tiles)
        origin, rot, (az_lo, az_hi, el_lo, el_hi) = window
        d = (self.centre - np.asarray(origin, float)) @ np.asarray(rot, float)
        r = np.linalg.norm(d, axis=1)
        inside = r <= self.radius * (1 + 1e-9)
        ang = np.arcsin(np.clip(self.radius / np.maximum(r, 1e-300), 0.0, 1.0))
        el = np.arcsin(np.clip(d[:, 1] / np.maximum(r, 1e-300), -1.0, 1.0))
        az = np.arctan2(d[:, 0], d[:, 2])
        # the azimuth span of a sphere widens as it nears the pole: a sphere reaching within
        # its angular radius of ±90° elevation may be at any azimuth
        cos_el = np.cos(np.minimum(np.abs(el) + ang, np.pi / 2))
        az_ang = np.where(cos_el > np.sin(ang), np.arcsin(np.clip(np.sin(ang) / np.maximum(cos_el, 1e-300), 0, 1)), np.pi)
        az_ok = (az + az_ang >= az_lo) & (az - az_ang <= az_hi)
        el_ok = (el + ang >= el_lo) & (el - ang <= el_hi)
        return np.flatnonzero(inside | (az_ok & el_ok))

    def specular_points(self, sources_m, receivers_m, *, cache: TileCache | None = None,
                        window=None, **kw):
        """:func:`acoustics.paths.specular.specular_points` over the floor, a tile at a time:
        the tiles the window reaches (all without one), facets numbered in the whole floor,
        rows sorted by pair then path length, a point found in two tiles (on their shared
        edge) kept once, as the whole mesh's search keeps it. ``cache``: the run's
        :class:`TileCache` of this floor (None: tiles built for this query only). The rows do
        not depend on what the cache holds."""
        from acoustics.paths.specular import SpecularPoints, specular_points
        from acoustics.paths.specular_search import search_blocks
        cache = TileCache(self) if cache is None else cache
        parts = []
        for k in cache.visit_order(self.tiles_in_window(window)):
            t = cache.tile(k)
            if t.blocks is None and kw.get("cull", True):
                t.blocks = search_blocks(t.vertices, t.faces, t.normals)
            sp = specular_points(t.vertices, t.faces, t.normals, sources_m, receivers_m,
                                 window=window, blocks=t.blocks, **kw)
            if len(sp):
                scale = np.linalg.norm(t.vertices[t.faces[sp.face, 1]] - t.vertices[t.faces[sp.face, 0]], axis=1)
                parts.append((sp, sp.face + t.face_start, scale))
        if not parts:
            return SpecularPoints.empty()
        names = ("pair", "face", "point_m", "normal", "source_range_m", "receiver_range_m",
                 "cos_incidence", "image_m", "divergence", "signature", "capped", "mesh_point_m")
        cols = {n: np.concatenate([getattr(sp, n) if n != "face" else f for sp, f, _ in parts])
                for n in names}
        scale = np.concatenate([s for _, _, s in parts])
        # the facet last: the same rows in any visiting order
        order = np.lexsort((cols["face"], cols["source_range_m"] + cols["receiver_range_m"], cols["pair"]))
        pair, x = cols["pair"][order], cols["point_m"][order]
        keep = []
        for i in range(order.size):
            if not any(pair[u] == pair[i] and np.linalg.norm(x[u] - x[i]) < 1e-3 * scale[order[i]] + 1e-9
                       for u in keep[-8:]):
                keep.append(i)
        sel = order[np.asarray(keep, int)]
        return SpecularPoints(**{n: cols[n][sel] for n in names})


class TileCache:
    """The built tiles of one :class:`FloorTiles`, least recently used evicted once they would
    exceed the floor's ``effects.floor_tiles.memory_mb``: what a run fills as it queries the
    floor, owned by the run (its ray caster), never by the frozen floor.

    Parameters
    ----------
    floor : FloorTiles

    Attributes
    ----------
    cached_bytes, peak_cached_bytes : float
        Bytes of the tiles held now, and at most so far (never above ``memory_bytes``).
    builds : int
        Tiles built so far (a tile evicted and needed again is built again).
    """

    def __init__(self, floor: FloorTiles):
        self.floor = floor
        self.memory_bytes = floor.memory_bytes
        self.tiles: OrderedDict[int, Tile] = OrderedDict()
        self.cached_bytes = 0.0
        self.peak_cached_bytes = 0.0
        self.builds = 0

    def __len__(self) -> int:
        return len(self.tiles)

    def tile(self, k: int) -> Tile:
        """Tile k, held or built (evicting the least recently used tiles first)."""
        k = int(k)
        t = self.tiles.get(k)
        if t is not None:
            self.tiles.move_to_end(k)
            return t
        f = self.floor
        need = tile_bytes_of(int(f.face_start[k + 1] - f.face_start[k]))
        while self.tiles and self.cached_bytes + need > self.memory_bytes:
            _, old = self.tiles.popitem(last=False)
            self.cached_bytes -= old.nbytes
        t = f.build(k)
        self.builds += 1
        self.tiles[k] = t
        self.cached_bytes += t.nbytes
        self.peak_cached_bytes = max(self.peak_cached_bytes, self.cached_bytes)
        return t

    def visit_order(self, tiles) -> list:
        """``tiles`` (indices) in the order to visit them: those held, most recently used
        first, then the others in index order — a scan that follows the previous one's tail
        finds it still built (a least-recently-used cache scanned in one order every time
        misses on every tile once it holds fewer than the scan). What a query returns does not
        depend on the order."""
        want = set(int(k) for k in tiles)
        held = [k for k in reversed(self.tiles) if k in want]
        kept = set(held)
        return held + [int(k) for k in tiles if int(k) not in kept]

    def rays_per_tile(self, origins, directions, reach, pad: float):
        """:meth:`FloorTiles.rays_per_tile`, the tiles in :meth:`visit_order`."""
        per_tile = dict(self.floor.rays_per_tile(origins, directions, reach, pad))
        return [(k, per_tile[k]) for k in self.visit_order(list(per_tile))]
