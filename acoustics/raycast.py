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

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

__all__ = ["Hits", "RayCaster"]

_MIN_CHUNK = 32_768


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
    normal : ndarray, shape (n, 3)
        Unit normal of the face hit, as stored in the mesh; zeros for a miss.
    """

    face: np.ndarray
    mesh: np.ndarray
    distance: np.ndarray
    point: np.ndarray
    normal: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.face >= 0


class RayCaster:
    """Embree scene of a list of :class:`~acoustics.meshes.SceneMesh` (sonar frame).

    Parameters
    ----------
    meshes : list of SceneMesh
    threads : int, optional
        Threads per batch; default every core.
    robust : bool
        Embree's robust (watertight) traversal.
    """

    def __init__(self, meshes, *, threads: int | None = None, robust: bool = True):
        import os
        self.meshes = list(meshes)
        if not self.meshes:
            raise ValueError("a ray caster needs at least one mesh")
        verts, faces, owner = [], [], []
        offset = 0
        for i, sm in enumerate(self.meshes):
            v = np.asarray(sm.mesh.vertices, float)
            f = np.asarray(sm.mesh.faces, np.int64)
            verts.append(v)
            faces.append(f + offset)
            owner.append(np.full(len(f), i))
            offset += len(v)
        self.vertices = np.concatenate(verts)
        self.faces = np.concatenate(faces)
        self.face_mesh = np.concatenate(owner)
        tri = self.vertices[self.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(n, axis=1)
        self.face_normal = n / np.where(norm > 0, norm, 1.0)[:, None]
        self.face_v0 = tri[:, 0].copy()
        self.extent_m = float(np.max(np.abs(self.vertices))) if len(self.vertices) else 1.0
        self.eps_m = max(64 * np.spacing(np.float32(max(self.extent_m, 1.0))).item(), 1e-7)
        self.threads = threads or os.cpu_count() or 1
        self._scene = rtcore_scene.EmbreeScene(robust=robust)
        TriangleMesh(scene=self._scene, vertices=self.vertices.astype(np.float32),
                     indices=self.faces.astype(np.int32))
        self.rays_cast: dict[str, int] = {}

    # ------------------------------------------------------------------ queries
    def _run(self, o32, d32, dists, query):
        n = o32.shape[0]
        if n == 0:
            return np.zeros(0, np.int32)
        chunks = min(self.threads, max(1, n // _MIN_CHUNK))
        if chunks <= 1:
            return self._scene.run(o32, d32, dists=dists, query=query)
        bounds = np.linspace(0, n, chunks + 1).astype(int)
        parts = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]

        def job(s):
            return self._scene.run(o32[s], d32[s], dists=None if dists is None else dists[s],
                                   query=query)

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
        directions : array_like, shape (n, 3)
            Normalised here.
        max_distance_m : float or array_like (n,), optional
        from_surface : bool
            The origins lie on a surface: start ε along the ray.
        purpose : str
            Counter name.
        """
        o = np.asarray(origins_m, float).reshape(-1, 3)
        d = np.asarray(directions, float).reshape(-1, 3)
        nrm = np.linalg.norm(d, axis=1)
        if np.any(nrm == 0) or not np.all(np.isfinite(o)) or not np.all(np.isfinite(d)):
            raise ValueError("rays need finite origins and non-zero finite directions")
        d = d / nrm[:, None]
        start = o + d * self.eps_m if from_surface else o
        dists = None
        if max_distance_m is not None:
            tmax = np.broadcast_to(np.asarray(max_distance_m, float), (o.shape[0],))
            dists = np.ascontiguousarray(np.maximum(tmax - (self.eps_m if from_surface else 0.0), 0.0),
                                         dtype=np.float32)
        self._count(purpose, o.shape[0])
        face = np.asarray(self._run(np.ascontiguousarray(start, np.float32),
                                    np.ascontiguousarray(d, np.float32), dists, "INTERSECT"),
                          np.int64)
        hit = face >= 0
        f = np.where(hit, face, 0)
        nf = self.face_normal[f]
        denom = np.einsum("ij,ij->i", nf, d)
        t = np.einsum("ij,ij->i", nf, self.face_v0[f] - o) / np.where(denom != 0, denom, 1.0)
        t = np.where(hit, t, np.inf)
        if dists is not None:
            # float32 may admit a hit just beyond the limit: the float64 distance decides
            beyond = hit & (t > np.asarray(max_distance_m, float) + self.eps_m)
            hit &= ~beyond
            t = np.where(hit, t, np.inf)
        face = np.where(hit, face, -1)
        point = np.where(hit[:, None], o + np.where(hit, t, 0.0)[:, None] * d, o)
        return Hits(face, np.where(hit, self.face_mesh[f], -1), t, point,
                    np.where(hit[:, None], nf, 0.0))

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
        res = self._run(np.ascontiguousarray(start, np.float32), np.ascontiguousarray(d, np.float32),
                        np.ascontiguousarray(np.maximum(reach, 0.0), np.float32), "OCCLUDED")
        out[ok] = np.asarray(res) == 0
        return out

    @property
    def total_rays(self) -> int:
        return int(sum(self.rays_cast.values()))
