"""The ray-traced scene: what meshes add to a ping's scatterers.

Every effect below produces *virtual scatterers* — a transmit-leg end point, a receive-leg start
point and a complex strength (m) — that go through the same per-element synthesis as point
targets (acoustics.synthesis). Each runs only when the scene calls for it:

``occlusion``      point targets whose transmit or receive path a mesh blocks lose their direct
                   echo (segments from the transmitter's and the receiver's phase centres);
``reverberation``  rays from the transmitter fill its beam down to a level; each first hit on a
                   boundary with a scattering law becomes a facet scatterer of footprint
                   A = r² ΔΩ / cos θ_inc and strength √(s_b A) e^{jϕ}, s_b from Lambert's law
                   and ϕ a random phase, frozen for static geometry (seeded);
``multipath``      specular paths by image sources on planar boundaries, up to K bounces per leg,
                   each bounce point checked on its mesh and every segment checked for
                   blockage by ray casting; strength × Π R(θ_inc) (reflection coefficients);
                   on any other reflecting mesh (a wavy sea) one bounce per leg through each of
                   its specular points (acoustics/paths/specular.py), with the curved mirror's
                   divergence factor;
``mesh_targets``   facets of mesh targets facing the transmitter and visible from it, each a
                   scatterer of physical-optics strength (jk/2π)(−n̂·k̂) ∫ e^{−2jk k̂·x} dS
                   (Gordon's exact triangle integral), computed once for static geometry.

A scene without meshes never builds a ray caster. A sea surface that moves (``wind_sea``,
``swell``) is moved to each ping's time by :meth:`RayScene.advance`, which rebuilds the caster and
drops what depended on the old surface.

**Frames.** Embree's scene is built once, in the sonar frame at rest (the mounting pose,
``sonar.pose``): for a still platform that is every ping's sonar frame. When the platform moves
the meshes stay where they are and the sonar moves among them: each method takes the ping's
``view``, the pose of that ping's sonar frame *in the frame the scene was built in*
(x_built = view.to_world(x_ping)); points and directions go in through it and the virtual
scatterers come back out in the ping's sonar frame. So nothing is rebuilt per ping — only what
depends on where the sonar is (reverberation rays, lit facets of mesh targets) is recomputed for
each new view.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from acoustics.frames import Pose
from acoustics.sonar.beams import illuminated_extent
from acoustics.paths.meshes import SceneMesh
from acoustics.medium import Medium
from acoustics.paths.raycast import RayCaster
from acoustics.paths.scattering import lambert_sb, rayleigh_reflection, triangle_phase_integral
from acoustics.seeds import FIXED, ping_rng
from acoustics.synthesis.scatterers import VirtualScatterers

__all__ = ["RayScene", "build_ray_scene"]


def _into(view: Pose | None, xyz):
    """Ping sonar-frame points (..., 3) in the frame the scene was built in."""
    return np.asarray(xyz, float) if view is None else view.to_world(xyz)


def _out_of(view: Pose | None, xyz):
    """Points (..., 3) of the built frame in the ping's sonar frame."""
    return xyz if view is None else view.to_sonar(xyz)


def _mirror(x, plane):
    n, d = plane
    return x - 2.0 * ((x @ n) - d)[..., None] * n


@dataclass
class RayScene:
    """Meshes, their caster, and what is fixed for a run (planes, facets), in the frame the
    scene was built in; ``tx_center`` and ``rx_center`` are the sonar's phase centres there at
    rest (each method's ``view`` moves them)."""

    meshes: list
    caster: RayCaster
    tx_center: np.ndarray
    rx_center: np.ndarray
    planes: dict
    medium: Medium
    frequency_hz: float
    _reverb_rays: tuple | None = None
    _reverb_fan: tuple | None = None
    _mesh_target_scatterers: VirtualScatterers | None = None
    _mesh_target_view: bytes | None = None
    hit_sample: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    specular: object = None
    """The scene's ``effects.specular`` settings."""
    specular_capped: int = 0
    """Specular paths whose level the focusing limit capped (near a caustic), this run."""
    last_specular: list = field(default_factory=list)
    """(mesh index, start, SpecularPoints, visible) of the last ``multipath`` call (views)."""
    _normal_cache: dict = field(default_factory=dict)
    _block_cache: dict = field(default_factory=dict)
    time_s: float = 0.0
    prepared: bool = False
    """Whether :meth:`prepare` ran (once per run, before the first ping's queries)."""
    fan_extent_rad: tuple | None = None
    """(az_lo, az_hi, el_lo, el_hi) (rad) of the transmitter's principal cuts above
    ``effects.specular.beam_level_db`` in the sonar frame; None: specular search everywhere."""
    rx_fan_extent_rad: tuple | None = None
    """The same for one receiver element (a receive leg's bounce point outside it reaches the
    element below the level)."""

    # ------------------------------------------------------------------- the sea
    @property
    def moving(self) -> bool:
        """Whether a mesh (a sea surface) moves between pings."""
        return any(sm.moving for sm in self.meshes)

    def advance(self, time_s: float):
        """Move every sea surface to sea time ``time_s`` (s after the first ping) and rebuild
        the caster; what depended on the old geometry is dropped. Nothing happens for a
        scene whose meshes do not move, or when the time has not changed."""
        if not self.moving or time_s == self.time_s:
            return
        self.meshes = [sm.at_time(sm.spec.mesh.time_offset_s + time_s) if sm.moving else sm
                       for sm in self.meshes]
        counts = self.caster.rays_cast
        self.caster = RayCaster(self.meshes, threads=self.caster.threads, previous=self.caster)
        self.caster.rays_cast = counts
        self._reverb_rays = None
        self._mesh_target_scatterers = None
        self._mesh_target_view = None
        # a still mesh's vertex normals and search blocks stay (a rough floor's cost as much as
        # its search)
        still = {id(sm.mesh) for sm in self.meshes if not sm.moving}
        for cache in (self._normal_cache, self._block_cache):
            for key in [k for k in cache if k not in still]:
                del cache[key]
        self.time_s = float(time_s)

    # ---------------------------------------------------------------- occlusion
    def centers(self, view: Pose | None = None):
        """The transmitter's and the receiver's phase centres (m), each shape (3,), in the built
        frame for a sonar at ``view``."""
        return _into(view, self.tx_center), _into(view, self.rx_center)

    def shadowed(self, positions_m, view: Pose | None = None):
        """Point targets whose transmit or receive path a mesh blocks.

        Parameters
        ----------
        positions_m : array_like, shape (n, 3)
            Sonar-frame positions (m) of this ping.
        view : Pose, optional
            This ping's sonar frame in the frame the scene was built in (None: the same).

        Returns
        -------
        ndarray of bool, shape (n,)
        """
        p = _into(view, np.asarray(positions_m, float).reshape(-1, 3))
        if p.shape[0] == 0:
            return np.zeros(0, bool)
        tx_c, rx_c = self.centers(view)
        tx = self.caster.occluded(np.broadcast_to(tx_c, p.shape), p, purpose="occlusion")
        rx = self.caster.occluded(np.broadcast_to(rx_c, p.shape), p, purpose="occlusion")
        return tx | rx

    # ------------------------------------------------------------ reverberation
    def reverberation(self, setup, ping: int, seed: int,
                      view: Pose | None = None) -> VirtualScatterers:
        """Facet scatterers of the boundaries the transmit beam lights, in the ping's sonar frame.

        ``setup`` (acoustics/simulation/setup.py) gives the fan's settings
        (``setup.effects.reverberation``), the record's length, the transmitter and the medium.
        For a still sonar (``view`` None) the rays are cast once and their phases frozen unless
        ``refresh_phase``; a moving sonar lights other patches every ping, so its rays are cast
        from each ping's view and the phases drawn anew.
        """
        spec = setup.effects.reverberation
        if view is None and not self.moving:
            if self._reverb_rays is None:
                self._reverb_rays = self._cast_reverberation_rays(setup, seed)
            pts, amp, n = self._reverb_rays
        else:
            pts, amp, n = self._cast_reverberation_rays(setup, seed, view)
        if n == 0:
            return VirtualScatterers.empty()
        if spec.refresh_phase or view is not None or self.moving:
            phase = ping_rng(seed, ping, "reverberation", 3).uniform(-np.pi, np.pi, n)
        else:
            phase = ping_rng(seed, FIXED, "reverberation", 3).uniform(-np.pi, np.pi, n)
        return VirtualScatterers(pts, pts.copy(), amp * np.exp(1j * phase),
                                 np.full(n, "reverberation"))

    def _reverberation_fan(self, spec, setup, seed):
        """The fan's unit directions (n, 3) in the sonar frame and their solid angles (n,) (sr):
        fixed for a run (frozen jitter), so made once, whatever the views."""
        key = (spec.beam_level_db, spec.rays_per_square_degree, int(seed))
        if self._reverb_fan is not None and self._reverb_fan[0] == key:
            return self._reverb_fan[1]
        tx = setup.sonar.transmitter
        lvl = spec.beam_level_db
        kw = dict(medium=setup.medium, frequency_hz=self.frequency_hz)
        # the fan covers every lobe above the level, sidelobes included: a floor lit by an
        # elevation sidelobe echoes at its own range, as it does at sea
        az_lo, az_hi = illuminated_extent(tx, plane="azimuth", level_db=lvl, **kw)
        el_lo, el_hi = illuminated_extent(tx, plane="elevation", level_db=lvl, **kw)
        dens = spec.rays_per_square_degree
        n_az = max(2, int(np.ceil(np.degrees(az_hi - az_lo) * np.sqrt(dens))))
        n_el = max(2, int(np.ceil(np.degrees(el_hi - el_lo) * np.sqrt(dens))))
        rng = ping_rng(seed, FIXED, "reverberation", 1)
        ia, ie = np.meshgrid(np.arange(n_az), np.arange(n_el), indexing="ij")
        d_az, d_el = (az_hi - az_lo) / n_az, (el_hi - el_lo) / n_el
        # jittered grid: one ray per cell at a random place in it (frozen)
        az = az_lo + (ia.ravel() + rng.random(ia.size)) * d_az
        el = el_lo + (ie.ravel() + rng.random(ie.size)) * d_el
        u = np.stack([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)], -1)
        solid = np.cos(el) * d_az * d_el
        self._reverb_fan = (key, (u, solid))
        return u, solid

    def _cast_reverberation_rays(self, setup, seed, view: Pose | None = None):
        spec = setup.effects.reverberation
        u, solid = self._reverberation_fan(spec, setup, seed)
        s = setup.sampling
        c = setup.medium.sound_speed_m_s
        r_max = spec.max_range_m or c * (s.time_offset_s + s.samples / s.rate_hz) / 2
        tx_c = _into(view, self.tx_center)
        if view is not None:
            u = view.direction_to_world(u)
        hits = self.caster.first_hit(np.broadcast_to(tx_c, u.shape), u,
                                     max_distance_m=r_max, purpose="reverberation")
        keep = hits.hit.copy()
        mu = np.zeros(len(self.meshes))
        for i, sm in enumerate(self.meshes):
            law = getattr(sm.spec, "scattering", None) if sm.kind == "boundary" else None
            if law is None:
                mu[i] = np.nan
            else:
                mu[i] = law.mu_db
        keep &= np.isfinite(mu[np.where(hits.hit, hits.mesh, 0)]) & hits.hit
        if not keep.any():
            return np.zeros((0, 3)), np.zeros(0), 0
        r = hits.distance[keep]
        cos_inc = np.clip(np.abs(np.einsum("ij,ij->i", u[keep], hits.normal[keep])), 1e-9, 1.0)
        grazing = np.pi / 2 - np.arccos(cos_inc)
        area = r**2 * solid[keep] / cos_inc
        sb = lambert_sb(grazing, 0.0) * 10.0 ** (mu[hits.mesh[keep]] / 10.0)
        pts = _out_of(view, hits.point[keep])
        take = np.linspace(0, pts.shape[0] - 1, min(2000, pts.shape[0])).astype(int)
        self.hit_sample = pts[take]
        return pts, np.sqrt(sb * area), int(keep.sum())

    # ----------------------------------------------------------------- multipath
    def _reflection(self, mesh_index, cos_inc):
        spec = self.meshes[mesh_index].spec.reflection
        if spec is None:
            return np.zeros_like(cos_inc, complex)
        if spec.model == "constant":
            return np.full(cos_inc.shape, complex(spec.coefficient))
        return rayleigh_reflection(np.arccos(np.clip(cos_inc, 0.0, 1.0)),
                                   density_ratio=spec.density_kg_m3 / spec.water_density_kg_m3,
                                   speed_ratio=spec.sound_speed_m_s / self.medium.sound_speed_m_s)

    def _unfold(self, start, end, seq):
        """Image of ``end`` seen from ``start`` through bounces ``seq``; validity and Π R.

        Returns image (n, 3), valid (n,), coefficient (n,) complex."""
        n = end.shape[0]
        image = end.copy()
        for b in reversed(seq):
            image = _mirror(image, self.planes[b])
        valid = np.ones(n, bool)
        coef = np.ones(n, complex)
        cur = np.broadcast_to(start, end.shape).copy()
        remaining = image.copy()
        for i, b in enumerate(seq):
            nrm, d = self.planes[b]
            v = remaining - cur
            den = v @ nrm
            t = np.divide(d - cur @ nrm, den, out=np.full(n, -1.0), where=np.abs(den) > 1e-15)
            valid &= (t > 0) & (t < 1)
            bounce = cur + np.clip(t, 0, 1)[:, None] * v
            seg = bounce - cur
            length = np.linalg.norm(seg, axis=1)
            dirs = seg / np.maximum(length, 1e-300)[:, None]
            # the bounce point must be on this boundary's mesh, first thing along the segment
            hits = self.caster.first_hit(cur, np.where(valid[:, None], dirs, [0, 0, 1.0]),
                                         from_surface=i > 0, purpose="multipath")
            on = hits.hit & (hits.mesh == b) & (np.abs(hits.distance - length) <= 10 * self.caster.eps_m
                                                  + 1e-9 * length)
            valid &= on
            coef *= self._reflection(b, np.abs(dirs @ nrm))
            remaining = _mirror(remaining, self.planes[b])
            cur = bounce
        # last segment, bounce -> end, must be clear
        if len(seq):
            valid &= ~self.caster.occluded(cur, end, purpose="multipath", start_on_surface=True)
        return image, valid, coef

    @property
    def curved(self) -> list:
        """Boundaries that reflect and are not planar: their specular paths come from their
        specular points (acoustics/paths/specular.py), one bounce per leg."""
        return [i for i, sm in enumerate(self.meshes)
                if sm.kind == "boundary" and getattr(sm.spec, "reflection", None) is not None
                and i not in self.planes]

    @property
    def reflectors(self) -> bool:
        """Whether any boundary gives specular paths."""
        return bool(self.planes) or bool(self.curved)

    def _normals(self, i):
        sm = self.meshes[i]
        if sm.normals is not None:
            return sm.normals
        key = id(sm.mesh)
        if key not in self._normal_cache:
            from acoustics.paths.specular import vertex_normals
            self._normal_cache[key] = vertex_normals(sm.mesh.vertices, sm.mesh.faces)
        return self._normal_cache[key]

    def _search_blocks(self, i):
        """A still whole mesh's search blocks (acoustics/paths/specular_search.py
        ``search_blocks``), made once per run; None for a moving or tiled one (its own)."""
        from acoustics.paths.tiles import is_tiled
        sm = self.meshes[i]
        if sm.moving or is_tiled(sm.mesh):
            return None
        key = id(sm.mesh)
        if key not in self._block_cache:
            from acoustics.paths.specular_search import search_blocks
            self._block_cache[key] = search_blocks(sm.mesh.vertices, sm.mesh.faces,
                                                   self._normals(i))
        return self._block_cache[key]

    def prepare(self, setup, seed: int):
        """What a run makes once, before its first ping's queries, so that no ping pays for
        it: the still meshes' Embree scene committed (its BVH), the still curved reflectors'
        vertex normals and search blocks (when paths bounce), the reverberation fan (when
        boundaries reverberate). Changes no result.

        Parameters
        ----------
        setup : Setup
            The run's set-up (acoustics/simulation/setup.py): its effects say what is needed.
        seed : int
            The run's seed (the fan's frozen jitter).
        """
        self.prepared = True
        self.caster.commit()
        fx = setup.effects
        if fx.max_bounces > 0:
            for i in self.curved:
                self._search_blocks(i)
        if fx.reverberation is not None:
            self._reverberation_fan(fx.reverberation, setup, seed)

    def specular_legs(self, start, ends, velocities=None, start_velocity=None, *,
                      window_extent=None, view=None):
        """One-bounce legs from ``start`` to each of ``ends`` off every curved boundary.

        Parameters
        ----------
        start : ndarray, shape (3,)
            A phase centre (m), built frame.
        ends : ndarray, shape (n, 3)
            Target positions (m), built frame.

        Returns
        -------
        target : ndarray of int, shape (k,)
        image : ndarray, shape (k, 3)
            Unfolded images (m), built frame.
        coefficient : ndarray, shape (k,), complex
            R(θ) × the curved mirror's divergence factor.
        rate : ndarray, shape (k,)
            dL/dt of each leg's length (m/s): the target's velocity along the last segment,
            the start's along the first, and the sea's vertical velocity at the bounce point
            (by stationarity only the surface's motion at fixed (x, y) changes the length to
            first order: dL = b_z dz, b the legs' bisector in the sea's frame). Zeros without
            velocities.

        The bounce points themselves are kept in ``last_specular`` (views, tests).
        """
        # one bounce off each curved boundary: the bounce sequences of one curved mesh
        rows = [self._curved_leg(start, ends, (i,), velocities, start_velocity,
                                 window_extent=window_extent, view=view) for i in self.curved]
        rows = [r for r in rows if r[0].size]
        if not rows:
            return np.zeros(0, int), np.zeros((0, 3)), np.zeros(0, complex), np.zeros(0)
        return tuple(np.concatenate(col) for col in list(zip(*rows))[:4])

    @staticmethod
    def _specular_rate(sm, start, ends, sp, sel, velocities, start_velocity):
        x = sp.point_m[sel]
        p = ends[sp.pair[sel]]
        out = np.zeros(sel.size)
        if velocities is not None:
            out += np.einsum("ij,ij->i", (p - x) / sp.receiver_range_m[sel, None],
                             velocities[sp.pair[sel]])
        if start_velocity is not None:
            out += ((start - x) / sp.source_range_m[sel, None]) @ start_velocity
        if sm.moving:
            rot, shift = sm.placement[:3, :3], sm.placement[:3, 3]
            own = (x - shift) @ rot
            b = ((x - start) / sp.source_range_m[sel, None]
                 + (x - p) / sp.receiver_range_m[sel, None]) @ rot
            out += b[:, 2] * sm.surface.vertical_velocity(own[:, 0], own[:, 1], sm.time_s)
        return out

    def bounce_sequences(self, max_bounces: int) -> list:
        """Every sequence of reflecting boundaries (mesh indices, in the order a leg meets them)
        of 1 to ``max_bounces`` bounces: no boundary twice in a row, at most one curved
        boundary per leg (a curved bounce is found by its specular points between the images of
        the leg's ends in the planar boundaries around it); shortest first."""
        planes, curved = sorted(self.planes), self.curved
        out, frontier = [], [()]
        for _ in range(max_bounces):
            frontier = [s + (b,) for s in frontier for b in planes + curved
                        if (not s or s[-1] != b) and not (b in curved and any(x in curved for x in s))]
            out += frontier
        return out

    def _legs(self, start, p, order, velocities=None, start_velocity=None, *, window_extent=None,
              view=None, curved_targets=None):
        """Every leg from ``start`` to the targets ``p``: direct, and every bounce sequence of
        :meth:`bounce_sequences` (planar ones by image sources, one with a curved boundary
        through its specular points); as flat rows (target, point, Π R, bounces, dL/dt,
        sequence number, facet), velocities (m/s) in the built frame. Sequence number 0 is the
        direct leg, k ≥ 1 the k-th of :meth:`bounce_sequences`; facet is the curved bounce's
        facet (−1 without one). ``window_extent`` (az_lo, az_hi, el_lo, el_hi; rad, in ``view``'s
        frame): a fan that a curved bounce seen straight from ``start`` must lie in (the
        specular fan, effects.specular.beam_level_db); ``curved_targets``: the targets whose
        legs with a curved bounce are searched (all when None)."""
        n = p.shape[0]
        v = np.zeros((n, 3)) if velocities is None else velocities
        vs = np.zeros(3) if start_velocity is None else start_velocity

        def rate(points, idx, mirror=None):
            # L = |image − start|; the image moves with the target's velocity mirrored
            d = points - start
            u = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
            vt = v[idx] if mirror is None else mirror(v[idx])
            return np.einsum("ij,ij->i", u, vt) - u @ vs

        rows = [(np.arange(n), p, np.ones(n, complex), np.zeros(n, int), rate(p, np.arange(n)),
                 np.zeros(n, int), np.full(n, -1))]
        for number, seq in enumerate(self.bounce_sequences(order), start=1):
            if any(b not in self.planes for b in seq):
                sub = np.arange(n) if curved_targets is None else np.asarray(curved_targets, int)
                if not sub.size:
                    continue
                t, im, c, r, face = self._curved_leg(
                    start, p[sub], seq, None if velocities is None else velocities[sub], start_velocity,
                    window_extent=window_extent, view=view)
                rows.append((sub[t], im, c, np.full(t.size, len(seq)), r, np.full(t.size, number), face))
                continue
            image, valid, coef = self._unfold(start, p, seq)
            idx = np.flatnonzero(valid)

            def mirror_v(vel, seq=seq):
                for b in reversed(seq):
                    nrm = self.planes[b][0]
                    vel = vel - 2.0 * (vel @ nrm)[:, None] * nrm
                return vel

            rows.append((idx, image[idx], coef[idx], np.full(idx.size, len(seq)),
                         rate(image[idx], idx, mirror_v), np.full(idx.size, number),
                         np.full(idx.size, -1)))
        return tuple(np.concatenate(col) for col in zip(*rows))

    def _mirror_all(self, x, seq):
        """``x`` (..., 3) mirrored in the planes of ``seq``, first plane first."""
        for b in seq:
            x = _mirror(x, self.planes[b])
        return x

    def _mirror_vectors(self, vel, seq):
        for b in seq:
            nrm = self.planes[b][0]
            vel = vel - 2.0 * (vel @ nrm)[..., None] * nrm
        return vel

    def _curved_leg(self, start, p, seq, velocities=None, start_velocity=None, *, window_extent=None,
                    view=None):
        """Legs start → seq → target with one curved boundary in ``seq``: the specular points
        on it between the start's image in the planes before it and the target's image in the
        planes after it (the planar bounces unfold; the curved mirror's divergence is taken in
        the unfolded legs), every planar bounce point checked on its mesh and every segment for
        blockage. Returns (target, image, coefficient, dL/dt, facet) rows as :meth:`_legs`.
        ``window_extent``: the fan of :meth:`_legs`, applied where the curved bounce is the leg's
        first (seen straight from ``start``); after a planar bounce the search is exhaustive."""
        from acoustics.paths.specular import specular_points
        k = next(j for j, b in enumerate(seq) if b not in self.planes)
        ci, before, after = seq[k], seq[:k], seq[k + 1:]
        sm, spec = self.meshes[ci], self.specular
        n = p.shape[0]
        s_img = self._mirror_all(np.asarray(start, float), before)          # start, seen from X
        e_img = self._mirror_all(p, tuple(reversed(after)))                  # targets, seen from X
        exact = None
        if sm.moving and spec.exact_surface:
            # its slope and curvature bound (Σ a|k|, Σ a|k|²): the search's tight block bound
            k = np.linalg.norm(np.asarray(sm.surface.k_m, float), axis=1)
            a = np.abs(np.asarray(sm.surface.amplitude_m, float))
            exact = (lambda x, y, _s=sm.surface, _t=sm.time_s: _s.height(x, y, _t), sm.placement,
                     (float(a @ k), float(a @ (k * k))))
        window = None
        if window_extent is not None and not before:   # a fan: only blocks it reaches, seen from start
            window = (np.asarray(start, float), np.eye(3) if view is None else view.rotation, window_extent)
        from acoustics.paths.tiles import is_tiled
        if is_tiled(sm.mesh):      # a tile at a time, in the run's cache of tiles (the caster's)
            search = partial(sm.mesh.specular_points, cache=self.caster.tile_cache(ci))
        else:
            search = partial(specular_points, sm.mesh.vertices, sm.mesh.faces, self._normals(ci),
                             blocks=self._search_blocks(ci))
        sp = search(np.broadcast_to(s_img, (n, 3)), e_img,
                    newton_iterations=spec.newton_iterations,
                    focusing_limit_db=spec.focusing_limit_db, height_field=exact,
                    window=window, near_facets=spec.near_facets)
        empty = (np.zeros(0, int), np.zeros((0, 3)), np.zeros(0, complex), np.zeros(0),
                 np.zeros(0, int))
        if not len(sp):
            return empty
        if sp.capped.any():
            self.specular_capped += int(sp.capped.sum())
            self.caster._count("specular_capped_paths", int(sp.capped.sum()))
        lift = (2.0 * np.linalg.norm(sp.point_m - sp.mesh_point_m, axis=1)
                + 10 * self.caster.eps_m + 1e-5 * sp.source_range_m)
        wet = sp.point_m + lift[:, None] * sp.normal
        coef = self._reflection(ci, sp.cos_incidence) * sp.divergence
        ends = p[sp.pair]
        # start → (planes before) → X: the bounce points on their meshes, nothing in the way
        if before:
            x_seen, ok, c1 = self._unfold(np.asarray(start, float), wet, before)
            coef = coef * c1
        else:
            x_seen = sp.point_m
            ok = ~self.caster.occluded(np.broadcast_to(start, wet.shape), wet, purpose="multipath")
        # X → (planes after) → target
        if after:
            _, ok2, c2 = self._unfold(wet, ends, after)
            ok &= ok2
            coef = coef * c2
        else:
            ok &= ~self.caster.occluded(wet, ends, purpose="multipath")
        if not seq[1:] and not before:
            self.last_specular.append((ci, start, sp, ok))
        if not ok.any():
            return empty
        sel = np.flatnonzero(ok)
        # the unfolded leg: its length along the direction it leaves the start in
        d = x_seen[sel] - start
        u = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
        image = start + (sp.source_range_m[sel] + sp.receiver_range_m[sel])[:, None] * u
        vel = None if velocities is None else self._mirror_vectors(
            np.asarray(velocities, float), tuple(reversed(after)))
        v_s = None if start_velocity is None else self._mirror_vectors(
            np.asarray(start_velocity, float), before)
        r = self._specular_rate(sm, s_img, e_img, sp, sel, vel, v_s)
        return sp.pair[sel], image, coef[sel], r, sp.face[sel]

    def multipath(self, positions_m, strength, order: int, view: Pose | None = None, *,
                  velocities_m_s=None, sonar_velocity_m_s=None, tags: bool = False) -> VirtualScatterers:
        """Specular paths of point targets: up to ``order`` bounces per leg on every reflecting
        boundary (:meth:`bounce_sequences`: planar ones by image sources, curved ones by their
        specular points).

        Parameters
        ----------
        positions_m : array_like, shape (n, 3)
            Sonar-frame positions (m) of this ping.
        strength : array_like, shape (n,)
            Complex backscatter amplitudes (m).
        order : int
            ``effects.max_bounces``: bounces per leg.
        view : Pose, optional
            This ping's sonar frame in the frame the scene was built in (None: the same).
        velocities_m_s : array_like, shape (n, 3), optional
            The targets' velocities (m/s) in the ping's sonar frame axes; with
            ``sonar_velocity_m_s`` (3,) they give each path's rate of change of length, the
            scatterers' ``rate_m_s`` (m/s, transmit leg + receive leg, the moving sea
            included): its Doppler shift is −f0/c times it.
        tags : bool
            Also give each path's :class:`~acoustics.synthesis.scatterers.PathTags` (its
            target and its bounces, for the arrivals table).

        Returns
        -------
        VirtualScatterers
            Image points in the ping's sonar frame: every pair of a transmit leg and a receive
            leg of the same target but the direct pair, each bounce sequence once (a path
            reached twice — the same target, sequences and image points — counts once).
        """
        p = _into(view, np.asarray(positions_m, float).reshape(-1, 3))
        q = np.asarray(strength, complex).reshape(-1)
        self.last_specular = []
        if order < 1 or not self.reflectors or p.shape[0] == 0:
            return VirtualScatterers.empty()
        rot = None if view is None else view.rotation
        vel = None if velocities_m_s is None else np.asarray(velocities_m_s, float).reshape(-1, 3)
        v_s = None if sonar_velocity_m_s is None else np.asarray(sonar_velocity_m_s, float)
        if rot is not None:        # vectors of the ping's sonar axes into the built frame
            vel = None if vel is None else vel @ rot.T
            v_s = None if v_s is None else rot @ v_s
        tx_c, rx_c = self.centers(view)
        fan = self.fan_extent_rad is not None
        t_tgt, t_pt, t_c, t_nb, t_rate, t_seq, t_face = self._legs(tx_c, p, order, vel, v_s, view=view,
                                                    window_extent=self.fan_extent_rad)
        rx_targets = None
        if fan:
            # a receive leg's bounce pairs with every transmit leg of its target: only targets
            # the fan lights directly, or through a bounce, send such a path above the level
            az_lo, az_hi, el_lo, el_hi = self.fan_extent_rad
            d = p - tx_c
            if view is not None:
                d = d @ view.rotation
            r = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
            el = np.arcsin(np.clip(d[:, 1] / r, -1.0, 1.0))
            az = np.arctan2(d[:, 0], d[:, 2])
            lit = (el >= el_lo) & (el <= el_hi) & (az >= az_lo) & (az <= az_hi)
            lit[t_tgt[t_nb > 0]] = True
            rx_targets = np.flatnonzero(lit)
        r_tgt, r_pt, r_c, r_nb, r_rate, r_seq, r_face = self._legs(rx_c, p, order, vel, v_s, view=view,
                                                    window_extent=self.rx_fan_extent_rad,
                                                    curved_targets=rx_targets)
        # join the legs on the target: every transmit leg with every receive leg
        o = np.argsort(r_tgt, kind="stable")
        r_tgt, r_pt, r_c, r_nb, r_rate, r_seq, r_face = (a[o] for a in (r_tgt, r_pt, r_c, r_nb, r_rate,
                                                                      r_seq, r_face))
        lo = np.searchsorted(r_tgt, t_tgt, "left")
        hi = np.searchsorted(r_tgt, t_tgt, "right")
        cnt = hi - lo
        ti = np.repeat(np.arange(t_tgt.size), cnt)
        # lo[t] .. hi[t] for each transmit leg t, concatenated
        ri = np.arange(ti.size) - np.repeat(np.cumsum(cnt) - cnt - lo, cnt)
        bounced = (t_nb[ti] + r_nb[ri]) > 0
        ti, ri = ti[bounced], ri[bounced]
        if ti.size == 0:
            return VirtualScatterers.empty()
        # a path reached twice (two specular points of one sequence that converged to the same
        # point) counts once: same target, same sequences, image points within 0.1 mm. Image
        # sources give one path per sequence: only legs with a curved bounce can repeat
        curved = (t_face[ti] >= 0) | (r_face[ri] >= 0)
        if curved.sum() > 1:
            c_ti, c_ri = self.distinct_paths(ti[curved], ri[curved], t_tgt, t_seq, r_seq, t_pt, r_pt)
            if c_ti.size < int(curved.sum()):
                ti, ri = np.concatenate([ti[~curved], c_ti]), np.concatenate([ri[~curved], c_ri])
        rates = None if vel is None and v_s is None else t_rate[ti] + r_rate[ri]
        path_tags = None
        if tags:
            from acoustics.synthesis.scatterers import PathTags
            seqs = [()] + self.bounce_sequences(order)
            letters = [self.meshes[i].role[0].upper() for i in range(len(self.meshes))]
            names = [self.meshes[i].name for i in range(len(self.meshes))]

            def label(tx_n, rx_n, tx_f, rx_f):
                tx_s, rx_s = seqs[tx_n], tuple(reversed(seqs[rx_n]))
                seq = "-".join([letters[b] for b in tx_s] + ["T"] + [letters[b] for b in rx_s])
                def hop(b, f, curved):
                    return f"{names[b]}#{f}" if curved else names[b]
                via = [hop(b, tx_f, b not in self.planes) for b in tx_s]
                via += [hop(b, rx_f, b not in self.planes) for b in rx_s]
                return seq, ";".join(via)

            lab = [label(a, b, c, d) for a, b, c, d in zip(t_seq[ti], r_seq[ri], t_face[ti], r_face[ri])]
            path_tags = PathTags(target=t_tgt[ti].astype(np.int64),
                                 sequence=np.array([x[0] for x in lab], dtype=str),
                                 via=np.array([x[1] for x in lab], dtype=str))
        return VirtualScatterers(_out_of(view, t_pt[ti]), _out_of(view, r_pt[ri]),
                                 q[t_tgt[ti]] * t_c[ti] * r_c[ri], np.full(ti.size, "multipath"),
                                 rates, tags=path_tags)

    def distinct_paths(self, ti, ri, t_tgt, t_seq, r_seq, t_pt, r_pt, tol_m: float = 1e-4):
        """The joined legs (ti, ri) less repeats of one path: rows of the same target and
        bounce sequences whose transmit and receive image points agree within ``tol_m``."""
        tg, ts, rq, tp, rp = t_tgt[ti], t_seq[ti], r_seq[ri], t_pt[ti], r_pt[ri]
        length = np.linalg.norm(tp, axis=1) + np.linalg.norm(rp, axis=1)
        order = np.lexsort((length, rq, ts, tg))
        a, b = order[:-1], order[1:]
        same = ((tg[a] == tg[b]) & (ts[a] == ts[b]) & (rq[a] == rq[b])
                & (np.linalg.norm(tp[a] - tp[b], axis=1) < tol_m)
                & (np.linalg.norm(rp[a] - rp[b], axis=1) < tol_m))
        if not same.any():
            return ti, ri
        keep = np.ones(ti.size, bool)
        keep[b[same]] = False
        self.caster._count("duplicate_paths_dropped", int((~keep).sum()))
        return ti[keep], ri[keep]

    # -------------------------------------------------------------- mesh targets
    def mesh_targets(self, view: Pose | None = None) -> VirtualScatterers:
        """Physical-optics facet scatterers of every mesh target, in the ping's sonar frame
        (computed once per view: once for a still sonar)."""
        key = b"" if view is None else view.position_m.tobytes() + view.rotation.tobytes()
        if self._mesh_target_scatterers is not None and self._mesh_target_view == key:
            return self._mesh_target_scatterers
        tx_c = _into(view, self.tx_center)
        k = 2 * np.pi * self.frequency_hz / self.medium.sound_speed_m_s
        parts = []
        for i, sm in enumerate(self.meshes):
            if sm.kind != "target":
                continue
            tri = np.asarray(sm.mesh.triangles, float)
            c = tri.mean(axis=1)
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            n /= np.linalg.norm(n, axis=1)[:, None]
            v = c - tx_c
            dist = np.linalg.norm(v, axis=1)
            kh = v / dist[:, None]
            cosine = -np.einsum("ij,ij->i", n, kh)
            lit = cosine > 0
            if not lit.any():
                continue
            # visible: the first thing a ray from the transmitter meets is this facet
            hits = self.caster.first_hit(np.broadcast_to(tx_c, (int(lit.sum()), 3)), kh[lit],
                                         purpose="mesh_targets")
            faces = np.flatnonzero(self.caster.face_mesh == i)
            first_face = faces[0] if faces.size else 0
            own = hits.face - first_face == np.flatnonzero(lit)
            near = np.abs(hits.distance - dist[lit]) <= 1e-6 * dist[lit] + 10 * self.caster.eps_m
            vis = np.zeros_like(lit)
            vis[lit] = hits.hit & (own | ((hits.mesh == i) & near))
            if not vis.any():
                continue
            integ = triangle_phase_integral(tri[vis], -2 * k * kh[vis])
            f = 1j * k / (2 * np.pi) * cosine[vis] * integ
            if sm.role == "pressure_release":
                f = -f
            at = _out_of(view, c[vis])
            parts.append(VirtualScatterers(at, at.copy(), f, np.full(int(vis.sum()), "mesh_target")))
        self._mesh_target_scatterers = VirtualScatterers.concat(parts)
        self._mesh_target_view = key
        return self._mesh_target_scatterers


def build_ray_scene(meshes, sonar, medium, *, frequency_hz: float, specular=None,
                    threads: int | None = None) -> RayScene | None:
    """The ray-traced scene of a run, or None without meshes (no caster built).

    Parameters
    ----------
    meshes : list of SceneMesh
        Every boundary and mesh target, in the sonar frame the scene is built in
        (:func:`acoustics.paths.meshes.scene_meshes`; the run's: the mounting pose's).
    sonar : Sonar
        The arrays (transmit and receive phase centres).
    medium : Medium
    frequency_hz : float
        The carrier f0 (Hz).
    specular : SpecularSpec, optional
        The specular search's settings (``effects.specular``).
    threads : int, optional
        Threads for ray batches (default: every core).
    """
    if not meshes:
        return None
    meshes: list[SceneMesh] = list(meshes)
    caster = RayCaster(meshes, threads=threads)
    planes = {}
    for i, sm in enumerate(meshes):
        if sm.kind == "boundary" and getattr(sm.spec, "reflection", None) is not None \
                and not sm.moving:
            pl = sm.plane
            if pl is not None:
                planes[i] = pl
    rx = sonar.receiver.elements
    fan = rx_fan = None
    level = getattr(specular, "beam_level_db", None)
    if level is not None:
        kw = dict(medium=medium, frequency_hz=frequency_hz)
        fan = (*illuminated_extent(sonar.transmitter, plane="azimuth", level_db=level, **kw),
               *illuminated_extent(sonar.transmitter, plane="elevation", level_db=level, **kw))
        one = rx.subset([0])
        rx_fan = (*illuminated_extent(one, plane="azimuth", level_db=level, **kw),
                  *illuminated_extent(one, plane="elevation", level_db=level, **kw))
    return RayScene(meshes, caster, sonar.transmitter.phase_center_m, rx.phase_center_m, planes,
                    medium, frequency_hz, specular=specular,
                    fan_extent_rad=fan, rx_fan_extent_rad=rx_fan)
