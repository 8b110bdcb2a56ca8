"""One Embree scene for every mesh of a simulation, queried in batches (embreex, directly).

Built once from all boundary and target meshes (in the sonar frame) and reused for every ping while
the geometry is static. Results are flat arrays with index columns, as trimesh's ``intersects_id``:
one row per ray, ``face = -1`` for a miss.

Precision guards — Embree computes in float32:

- coordinates are local to the sonar (the meshes arrive in the sonar frame);
- hit distances are recomputed in float64 from the hit triangle's plane, t = n·(v0 − o)/(n·d);
- rays that start on a surface are moved off it by a scale-aware ε along the ray, and segments
  (occlusion) stop ε short of their ends, ε = 64 float32 ulps of the scene's extent;
- a first hit is one hit, so no duplicates; Embree's robust (watertight) mode keeps rays through
  shared edges and vertices from slipping between triangles.

Batches are split across threads (embreex releases the GIL during a query). The caster counts
the rays it casts, per purpose, so a run can prove which stages cast none.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba as nb
import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

__all__ = ["Hits", "RayCaster"]

_MIN_CHUNK = 32_768


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _prepare(o, d, eps, o32, d32):
    """The float32 rays Embree takes (unit directions, origins ``eps`` along the ray); False
    if an origin or direction is not finite or a direction is zero."""
    ok = True
    for i in range(o.shape[0]):
        n2 = d[i, 0] * d[i, 0] + d[i, 1] * d[i, 1] + d[i, 2] * d[i, 2]
        if not (n2 > 0.0 and n2 < np.inf):
            ok = False
            n2 = 1.0
        inv = 1.0 / np.sqrt(n2)
        for j in range(3):
            u = d[i, j] * inv
            if not np.isfinite(o[i, j]):
                ok = False
            d32[i, j] = u
            o32[i, j] = o[i, j] + eps * u
    return ok


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _refine(face, o, d, face_plane, face_mesh, limit, out_face, out_mesh, out_t, out_p):
    """float64 distance t = (n·v0 − n·o)/(n·d) of each hit from its triangle's plane
    (face_plane rows: n, n·v0); a hit past ``limit`` (float32 may admit one just beyond it) is
    a miss."""
    scalar_limit = limit.shape[0] == 1
    for i in range(face.shape[0]):
        f = face[i]
        t = np.inf
        inv = 1.0 / np.sqrt(d[i, 0] * d[i, 0] + d[i, 1] * d[i, 1] + d[i, 2] * d[i, 2])
        ux, uy, uz = d[i, 0] * inv, d[i, 1] * inv, d[i, 2] * inv
        if f >= 0:
            nx, ny, nz, nd = face_plane[f, 0], face_plane[f, 1], face_plane[f, 2], face_plane[f, 3]
            den = nx * ux + ny * uy + nz * uz
            num = nd - (nx * o[i, 0] + ny * o[i, 1] + nz * o[i, 2])
            t = num / den if den != 0.0 else 0.0
            if t > limit[0 if scalar_limit else i]:
                f = -1
                t = np.inf
        out_face[i] = f
        out_mesh[i] = face_mesh[f] if f >= 0 else -1
        out_t[i] = t
        tt = t if f >= 0 else 0.0
        out_p[i, 0] = o[i, 0] + tt * ux
        out_p[i, 1] = o[i, 1] + tt * uy
        out_p[i, 2] = o[i, 2] + tt * uz


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _may_reach(o32, d32, dists, centre, axes, lo, hi):
    """Whether any ray (origin ``o32``, unit direction ``d32``, float32; as far as ``dists``,
    or without end when None) meets the box [lo, hi] in the frame of ``axes`` (columns) about
    ``centre`` (float64 slabs)."""
    for i in range(o32.shape[0]):
        t0 = 0.0
        t1 = np.inf if dists is None else float(dists[i])
        for j in range(3):
            o = 0.0
            d = 0.0
            for m in range(3):
                o += (float(o32[i, m]) - centre[m]) * axes[m, j]
                d += float(d32[i, m]) * axes[m, j]
            if d == 0.0:
                if o < lo[j] or o > hi[j]:
                    t0 = 1.0
                    t1 = 0.0
                    break
                continue
            a = (lo[j] - o) / d
            b = (hi[j] - o) / d
            if a > b:
                a, b = b, a
            t0 = max(t0, a)
            t1 = min(t1, b)
        if t0 <= t1:
            return True
    return False


@dataclass(frozen=True)
class Hits:
    """First hits of a batch of rays, one row per ray.

    Attributes
    ----------
    face : ndarray of int, shape (n,)
        Index into the caster's concatenated faces; -1 for a miss.
    mesh : ndarray of int, shape (n,)
        Index of the mesh hit (into the caster's list); -1 for a miss.
    distance : ndarray, shape (n,)
        Distance (m) along the ray, float64 from the triangle; inf for a miss.
    point : ndarray, shape (n, 3)
        Hit points (m); NaN-free: the ray's origin for a miss.
    face_normals : ndarray, shape (F, 3)
        The caster's unit face normals of its whole meshes (shared, not copied).
    row_normals : ndarray, shape (n, 3), optional
        Each row's face normal, given when a tiled floor was hit (its facets have no row in
        ``face_normals``).
    """

    face: np.ndarray
    mesh: np.ndarray
    distance: np.ndarray
    point: np.ndarray
    face_normals: np.ndarray
    row_normals: np.ndarray | None = None

    @property
    def hit(self) -> np.ndarray:
        return self.face >= 0

    @property
    def normal(self) -> np.ndarray:
        """Unit normal (n, 3) of the face hit, as stored in the mesh; zeros for a miss."""
        if self.row_normals is not None:
            return np.where(self.hit[:, None], self.row_normals, 0.0)
        return np.where(self.hit[:, None], self.face_normals[np.maximum(self.face, 0)], 0.0)


def _same_layout(previous, meshes, tiled):
    """Whether ``meshes`` hold the previous caster's whole meshes in its places: each the same
    object, or a moving one (a sea) with as many vertices and the same facets."""
    if len(previous.meshes) != len(meshes) or previous._tiled or tiled.any():
        return False
    for a, b in zip(previous.meshes, meshes):
        if a is b:
            continue
        if not (getattr(a, "moving", False) and getattr(b, "moving", False)):
            return False
        va, vb = a.mesh.vertices, b.mesh.vertices
        fa, fb = a.mesh.faces, b.mesh.faces
        if len(va) != len(vb) or not np.array_equal(fa, fb):
            return False
    return True


class RayCaster:
    """Embree scene of a list of :class:`~acoustics.meshes.SceneMesh` (sonar frame).

    One batch at a time: a caster reuses its float32 ray buffers between batches (each batch
    is itself split across threads).

    Parameters
    ----------
    meshes : list of SceneMesh
    threads : int, optional
        Threads per batch; default every core.
    robust : bool
        Embree's robust (watertight) traversal.
    """

    def __init__(self, meshes, *, threads: int | None = None, robust: bool = True,
                 previous: "RayCaster | None" = None):
        import os
        self.meshes = list(meshes)
        if not self.meshes:
            raise ValueError("a ray caster needs at least one mesh")
        verts, faces, owner, normal, v0 = [], [], [], [], []
        offset = 0
        self._per_mesh = {}
        # a floor in tiles (acoustics/paths/tiles.py.FloorTiles) says so
        tiled = np.array([bool(getattr(sm.mesh, "tiled", False)) for sm in self.meshes])
        # a new sea under the previous caster's still meshes, its facets as before: the
        # previous arrays, with the sea's rows written anew (the still rows are not copied
        # piecewise, the facets and their owners not at all)
        same = previous is not None and _same_layout(previous, self.meshes, tiled)
        changed = []
        for i, sm in enumerate(self.meshes):
            if tiled[i]:
                continue
            v = np.asarray(sm.mesh.vertices, float)
            f = np.asarray(sm.mesh.faces, np.int64)
            # a mesh's face normals, first vertices and largest coordinate, kept from the
            # previous caster when the mesh is the same object (a still floor under a moving sea)
            kept = None if previous is None else previous._per_mesh.get(id(sm))
            fresh = kept is None or kept[0] is not sm
            if fresh:
                tri = v[f]
                n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
                norm = np.linalg.norm(n, axis=1)
                kept = (sm, n / np.where(norm > 0, norm, 1.0)[:, None], tri[:, 0].copy(),
                        float(np.max(np.abs(v))) if len(v) else None)
                changed.append((i, offset, v, kept))
            self._per_mesh[id(sm)] = kept
            if not same:
                verts.append(v)
                faces.append(f + offset)
                owner.append(np.full(len(f), i))
                normal.append(kept[1])
                v0.append(kept[2])
            offset += len(v)

        def cat(parts, shape, dtype=float):
            return np.concatenate(parts) if parts else np.zeros(shape, dtype)

        if same:
            self.vertices = previous.vertices.copy()
            self.faces = previous.faces
            self.face_mesh = previous.face_mesh
            self.face_normal = previous.face_normal.copy()
            self.face_v0 = previous.face_v0.copy()
            self.face_plane = previous.face_plane.copy()
            for i, v_off, v, kept in changed:
                rows = previous._face_rows[i]
                self.vertices[v_off:v_off + len(v)] = v
                self.face_normal[rows] = kept[1]
                self.face_v0[rows] = kept[2]
                self.face_plane[rows, :3] = kept[1]
                self.face_plane[rows, 3] = np.einsum("ij,ij->i", kept[1], kept[2])
            self._face_rows = previous._face_rows
        else:
            self.vertices = cat(verts, (0, 3))
            self.faces = cat(faces, (0, 3), np.int64)
            self.face_mesh = cat(owner, (0,), np.int64)
            self.face_normal = cat(normal, (0, 3))
            self.face_v0 = cat(v0, (0, 3))
            # rows n, n·v0: one cache line per hit when refining
            self.face_plane = np.empty((self.faces.shape[0], 4))
            self.face_plane[:, :3] = self.face_normal
            self.face_plane[:, 3] = np.einsum("ij,ij->i", self.face_normal, self.face_v0)
            bounds = np.cumsum([0] + [len(x) for x in owner])
            whole = [i for i in range(len(self.meshes)) if not tiled[i]]
            self._face_rows = {i: slice(int(a), int(b)) for i, a, b in zip(whole, bounds[:-1], bounds[1:])}
        # tiled floors (acoustics/paths/tiles.py): their facets are numbered after the whole
        # meshes', (mesh index, the run's TileCache of the floor, first facet) each; never held
        # whole. The built tiles are the caster's (the run's), not the floor's (the frozen
        # set-up's); a caster rebuilt for a new sea keeps a still floor's tiles
        from acoustics.paths.tiles import TileCache
        self._tiled = []
        start = self.faces.shape[0]
        for i in np.flatnonzero(tiled):
            floor = self.meshes[i].mesh
            held = None if previous is None else next(
                (c for _, c, _ in previous._tiled if c.floor is floor), None)
            self._tiled.append((int(i), held if held is not None else TileCache(floor), start))
            start += floor.n_faces
        extents = [k[3] for k in self._per_mesh.values() if k[3] is not None]
        extents = [max(extents)] if extents else []
        extents += [tiles.floor.extent_m for _, tiles, _ in self._tiled]
        self.extent_m = max(extents) if extents else 1.0
        self.eps_m = max(64 * np.spacing(np.float32(max(self.extent_m, 1.0))).item(), 1e-7)
        self.threads = threads or os.cpu_count() or 1
        # one Embree scene for the meshes that never move, one for those that do (a sea): a
        # caster rebuilt for a new sea (``previous``) keeps the still meshes' scene and its BVH;
        # the moving meshes' scene is built when a batch of rays first may reach their box
        # (rays that cannot reach it cannot hit it: a ping whose rays all stay below a sea
        # never builds it)
        moving = np.array([bool(getattr(sm, "moving", False)) for sm in self.meshes])
        self._parts = []
        self._lazy = {}
        self._lock = threading.Lock()
        self._robust = robust
        for flag in (False, True):
            idx = np.flatnonzero((moving == flag) & ~tiled)
            if idx.size == 0:
                continue
            reused = None
            if previous is not None and not flag:
                reused = previous._still_part(self.meshes, idx)
            if reused is None and flag:
                self._lazy[len(self._parts)] = (idx, self._box(idx))
                reused = (None, None, [self.meshes[i] for i in idx], False)
            self._parts.append(reused if reused is not None else
                               self._build_part(idx, robust, still=not flag))
        self.rays_cast: dict[str, int] = {}
        self._buffers = None

    def first_face(self, mesh_index: int) -> int:
        """The caster's number of a mesh's first facet (facet k of the mesh is this + k).

        Parameters
        ----------
        mesh_index : int
            The mesh's index among the caster's meshes.

        Returns
        -------
        int
        """
        for i, _, start in self._tiled:
            if i == mesh_index:
                return start
        own = np.flatnonzero(self.face_mesh == mesh_index)
        return int(own[0]) if own.size else 0

    def tile_cache(self, mesh_index: int):
        """The :class:`~acoustics.paths.tiles.TileCache` this caster holds for a tiled floor
        (its built tiles; the floor itself is not changed by a query).

        Parameters
        ----------
        mesh_index : int
            The floor's index among the caster's meshes.

        Returns
        -------
        TileCache

        Raises
        ------
        KeyError
            The mesh is not a tiled floor.
        """
        for i, tiles, _ in self._tiled:
            if i == mesh_index:
                return tiles
        raise KeyError(f"mesh {mesh_index} of the ray caster is not a tiled floor")

    def _build_part(self, mesh_idx, robust, still):
        """(Embree scene, global face index of each of its faces, its meshes, still) for the
        meshes ``mesh_idx``."""
        faces = np.flatnonzero(np.isin(self.face_mesh, mesh_idx))
        verts, local, offset = [], [], 0
        for i in mesh_idx:      # each mesh's own vertices, its faces offset within the part
            m = self.meshes[i].mesh
            verts.append(np.asarray(m.vertices, np.float32))
            local.append(np.asarray(m.faces, np.int64) + offset)
            offset += len(m.vertices)
        scene = rtcore_scene.EmbreeScene(robust=robust)
        TriangleMesh(scene=scene, vertices=np.concatenate(verts),
                     indices=np.concatenate(local).astype(np.int32))
        return scene, faces.astype(np.int32), [self.meshes[i] for i in mesh_idx], still

    def _box(self, mesh_idx):
        """The box of the meshes ``mesh_idx`` along their principal axes (a sea tilted in the
        sonar's frame is a thin slab in its own): (centre (3,), axes (3, 3) as columns, lo (3,),
        hi (3,); m), grown by a margin far above Embree's float32 rounding (1 mm and 1e-5 of
        the scene's extent)."""
        v = np.concatenate([np.asarray(self.meshes[i].mesh.vertices, float) for i in mesh_idx])
        centre = v.mean(axis=0)
        axes = np.linalg.svd(v - centre, full_matrices=False)[2].T
        local = (v - centre) @ axes
        grow = 1e-3 + 1e-5 * self.extent_m + 100 * self.eps_m
        return (centre, np.ascontiguousarray(axes), local.min(axis=0) - grow,
                local.max(axis=0) + grow)

    def _part(self, k, o32, d32, dists):
        """Part ``k``'s Embree scene, built now if it is a lazy one that a ray of this batch
        may reach (None while none may: no ray of the batch can hit it)."""
        scene = self._parts[k][0]
        if scene is not None:
            return scene
        idx, (centre, axes, lo, hi) = self._lazy[k]
        if not _may_reach(o32, d32, dists, centre, axes, lo, hi):
            return None
        with self._lock:
            if self._parts[k][0] is None:
                self._parts[k] = self._build_part(idx, self._robust, still=False)
        return self._parts[k][0]

    def commit(self):
        """Build the Embree scenes made so far (their BVHs: Embree builds one on its first
        query), so that no later batch pays for it; casts no counted ray."""
        o = np.zeros((1, 3), np.float32)
        d = np.array([[0.0, 0.0, 1.0]], np.float32)
        for scene, _, _, _ in self._parts:
            if scene is not None:
                scene.run(o, d, query="OCCLUDED")

    def _still_part(self, meshes, mesh_idx):
        """This caster's scene of still meshes, if ``meshes[mesh_idx]`` are the same objects at
        the same face offsets (so its face indices hold in the new caster), else None."""
        for scene, faces, owned, still in self._parts:
            if not still or len(owned) != len(mesh_idx):
                continue
            if all(a is meshes[i] for a, i in zip(owned, mesh_idx)):
                mine = np.flatnonzero(np.isin(self.face_mesh, [self.meshes.index(a) for a in owned]))
                if np.array_equal(mine, faces) and self.faces.shape[0] > 0:
                    return scene, faces, owned, still
        return None

    def _ids(self, o32, d32, dists, query):
        """Embree's answer over every part: the global face hit (INTERSECT; the nearest over
        the parts, by Embree's float32 distance) or 0 where blocked (OCCLUDED, as Embree)."""
        # the parts a ray of the batch may reach (a lazy part none can reach is left out)
        parts = [(scene, self._parts[k][1]) for k in range(len(self._parts))
                 if (scene := self._part(k, o32, d32, dists)) is not None]
        if not parts:
            return np.full(o32.shape[0], -1, np.int32)
        if len(parts) == 1:
            scene, faces = parts[0]
            if query == "OCCLUDED":
                return np.asarray(scene.run(o32, d32, dists=dists, query=query))
            ids = np.asarray(scene.run(o32, d32, dists=dists, query=query))
            return np.where(ids >= 0, faces[np.maximum(ids, 0)], -1).astype(np.int32)
        if query == "OCCLUDED":
            free = np.ones(o32.shape[0], bool)
            for scene, _ in parts:
                free &= np.asarray(scene.run(o32, d32, dists=dists, query=query)) != 0
            return np.where(free, -1, 0).astype(np.int32)
        best = np.full(o32.shape[0], -1, np.int32)
        best_t = np.full(o32.shape[0], np.inf, np.float32)
        for scene, faces in parts:
            res = scene.run(o32, d32, dists=dists, query=query, output=1)
            ids = np.asarray(res["geomID"]) if isinstance(res, dict) else None
            prim = np.asarray(res["primID"])
            t = np.asarray(res["tfar"], np.float32)
            hit = (ids >= 0) & (prim >= 0)
            nearer = hit & (t < best_t)
            best[nearer] = faces[prim[nearer]]
            best_t[nearer] = t[nearer]
        return best

    # ------------------------------------------------------------------ queries
    def _run(self, o32, d32, dists, query):
        n = o32.shape[0]
        if n == 0:
            return np.zeros(0, np.int32)
        chunks = min(self.threads, max(1, n // _MIN_CHUNK))
        if chunks <= 1:
            return self._ids(o32, d32, dists, query)
        bounds = np.linspace(0, n, chunks + 1).astype(int)
        parts = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]

        def job(s):
            return self._ids(o32[s], d32[s], None if dists is None else dists[s], query)

        with ThreadPoolExecutor(chunks) as pool:
            return np.concatenate(list(pool.map(job, parts)))

    def _count(self, purpose: str, n: int):
        self.rays_cast[purpose] = self.rays_cast.get(purpose, 0) + int(n)

    def first_hit(self, origins_m, directions, *, max_distance_m=None, from_surface=False,
                  purpose: str = "rays") -> Hits:
        """First intersection of each ray.

        Parameters
        ----------
        origins_m : array_like, shape (n, 3)
            Ray origins (m), sonar frame.
        directions : array_like, shape (n, 3)
            Normalised here.
        max_distance_m : float or array_like (n,), optional
            Farthest hit accepted (m).
        from_surface : bool
            The origins lie on a surface: start ε along the ray.
        purpose : str
            Counter name.

        Returns
        -------
        Hits
            One row per ray.

        Raises
        ------
        ValueError
            A non-finite origin or direction, or a zero direction.
        """
        o = np.ascontiguousarray(np.asarray(origins_m, float).reshape(-1, 3))
        d = np.ascontiguousarray(np.asarray(directions, float).reshape(-1, 3))
        if o.shape != d.shape:
            raise ValueError("origins_m and directions must have the same shape (n, 3)")
        n = o.shape[0]
        eps = self.eps_m if from_surface else 0.0
        limit = np.array([np.inf]) if max_distance_m is None else np.ascontiguousarray(
            np.broadcast_to(np.asarray(max_distance_m, float), (n,)))
        face = np.empty(n, np.int32)
        mesh = np.empty(n, np.int32)
        t = np.empty(n)
        point = np.empty((n, 3))
        o32, d32 = self._scratch(n)
        self._count(purpose, n)

        def job(s):
            if not _prepare(o[s], d[s], eps, o32[s], d32[s]):
                return False
            if s.stop == s.start:
                return True
            dists = None
            if max_distance_m is not None:
                # Embree stops at the limit less the start offset; float64 has the last word
                dists = np.ascontiguousarray(np.maximum(limit[s] - eps, 0.0) * (1 + 1e-6) + self.eps_m,
                                             np.float32)
            ids = self._ids(o32[s], d32[s], dists, "INTERSECT")
            lim = limit[s] + self.eps_m if limit.shape[0] > 1 else limit + self.eps_m
            _refine(ids.astype(np.int32, copy=False), o[s], d[s], self.face_plane,
                    self.face_mesh, lim, face[s], mesh[s], t[s], point[s])
            return True

        if not all(self._map(job, n)):
            raise ValueError("rays need finite origins and non-zero finite directions")
        if not self._tiled:
            return Hits(face, mesh, t, point, self.face_normal)
        row_normal = np.zeros((n, 3))
        if self.face_normal.shape[0]:
            row_normal[face >= 0] = self.face_normal[face[face >= 0]]
        reach = limit + self.eps_m if limit.shape[0] > 1 else np.full(n, limit[0] + self.eps_m)
        self._tiled_first_hit(o, d, eps, o32, d32, reach, face, mesh, t, point, row_normal)
        return Hits(face, mesh, t, point, self.face_normal, row_normal)

    def _tiled_first_hit(self, o, d, eps, o32, d32, reach, face, mesh, t, point, row_normal):
        """The nearest hit on each tiled floor, a tile at a time (the tiles each ray's reach
        crosses), kept where nearer than the hit so far (float64 distances)."""
        for mi, tiles, start in self._tiled:
            for k, rows in tiles.rays_per_tile(o32, d32, reach, 16 * self.eps_m):
                tile = tiles.tile(k)
                dists = np.ascontiguousarray(np.minimum(reach[rows] - eps, 3e38) * (1 + 1e-6) + self.eps_m,
                                             np.float32)
                ids = np.asarray(tile.embree.run(o32[rows], d32[rows], dists=dists, query="INTERSECT"),
                                 np.int32)
                m = rows.size
                f_k, m_k, t_k, p_k = (np.empty(m, np.int32), np.empty(m, np.int32), np.empty(m),
                                      np.empty((m, 3)))
                _refine(ids, np.ascontiguousarray(o[rows]), np.ascontiguousarray(d[rows]),
                        tile.face_plane, np.full(tile.faces.shape[0], mi, np.int32),
                        np.ascontiguousarray(reach[rows]), f_k, m_k, t_k, p_k)
                g_k = start + tile.face_start + f_k
                # a tie (a ray through two tiles' shared edge) to the lower facet number: the
                # same hit in any order of the tiles
                near = (f_k >= 0) & ((t_k < t[rows]) | ((t_k == t[rows]) & (g_k < face[rows])))
                r = rows[near]
                face[r] = g_k[near]
                mesh[r] = mi
                t[r] = t_k[near]
                point[r] = p_k[near]
                row_normal[r] = tile.face_plane[f_k[near], :3]

    def _scratch(self, n):
        """float32 ray buffers for Embree, kept between batches (fresh pages cost as much as the
        conversion itself)."""
        if self._buffers is None or self._buffers[0].shape[0] < n:
            self._buffers = (np.empty((n, 3), np.float32), np.empty((n, 3), np.float32))
        return self._buffers[0][:n], self._buffers[1][:n]

    def _map(self, job, n):
        """Run ``job(slice)`` over contiguous chunks of n rows, one per thread."""
        chunks = min(self.threads, max(1, n // _MIN_CHUNK))
        if chunks <= 1:
            return [job(slice(0, n))]
        bounds = np.linspace(0, n, chunks + 1).astype(int)
        parts = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]
        with ThreadPoolExecutor(chunks) as pool:
            return list(pool.map(job, parts))

    def occluded(self, starts_m, ends_m, *, purpose: str = "occlusion", start_on_surface=False,
                 end_on_surface=True):
        """Whether a mesh blocks each segment start → end.

        The segment stops ε short of its end (a target on a surface is not blocked by that
        surface) and, with ``start_on_surface``, starts ε beyond its start.

        Returns
        -------
        ndarray of bool, shape (n,)
        """
        a = np.asarray(starts_m, float).reshape(-1, 3)
        b = np.asarray(ends_m, float).reshape(-1, 3)
        v = b - a
        length = np.linalg.norm(v, axis=1)
        out = np.zeros(a.shape[0], bool)
        ok = length > 3 * self.eps_m
        if not ok.any():
            return out
        d = v[ok] / length[ok, None]
        start = a[ok] + (d * self.eps_m if start_on_surface else 0.0)
        reach = length[ok] - (self.eps_m if start_on_surface else 0.0) - (self.eps_m if end_on_surface else 0.0)
        self._count(purpose, int(ok.sum()))
        s32, d32 = np.ascontiguousarray(start, np.float32), np.ascontiguousarray(d, np.float32)
        r32 = np.ascontiguousarray(np.maximum(reach, 0.0), np.float32)
        blocked = np.asarray(self._run(s32, d32, r32, "OCCLUDED")) == 0 if self._parts else \
            np.zeros(s32.shape[0], bool)
        for _, tiles, _ in self._tiled:
            for k, rows in tiles.rays_per_tile(s32, d32, r32, 16 * self.eps_m):
                rows = rows[~blocked[rows]]
                if rows.size:
                    res = tiles.tile(k).embree.run(s32[rows], d32[rows], dists=r32[rows], query="OCCLUDED")
                    blocked[rows] |= np.asarray(res) == 0
        out[ok] = blocked
        return out

    @property
    def total_rays(self) -> int:
        return int(sum(self.rays_cast.values()))
