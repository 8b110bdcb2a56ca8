"""Point targets for one ping: explicit points and random populations, seeded per ping.

Every draw comes from ``default_rng(SeedSequence([seed, ping, stream, group]))``: a ping's
targets depend only on the scene seed and that ping's index. Populations with ``redraw: false``
draw their positions once (the ping index is replaced by :data:`FIXED`); backscatter amplitudes
and random phases are drawn every ping — a fish's echo fluctuates from ping to ping even when it
holds its place.

Backscatter models (thesis §2.4.1): ``unit`` ρ = 1 m; ``fixed`` ρ = 10^(TS/20) m; ``rayleigh``
ρ from a Rayleigh law of scale s truncated to [lo, hi] by inverse-CDF sampling; ``swimbladder``
ρ and phase from the fish's bladder at its incidence angle this ping (:func:`swimbladder_backscatter`,
acoustics/targets/fish.py).
A population given by density draws a Poisson number of targets with mean density × volume
(a homogeneous Poisson point process), so counts vary from ping to ping as in the sea.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from acoustics.frames import Pose, spherical_to_cartesian
from acoustics.seeds import FIXED, ping_rng

__all__ = ["TargetSet", "Targets", "TargetPoint", "draw_targets", "point_positions_sonar",
           "draw_backscatter", "ID_BLOCK", "has_swimbladders", "swimbladder_backscatter"]


@dataclass(frozen=True)
class TargetPoint:
    """One explicit point target, resolved: its position in its frame.

    Attributes
    ----------
    frame : {"sonar", "world"}
    position_m : (float, float, float)
        Position (m) in ``frame`` (a scene's ⟨r, θ, φ⟩ is converted to sonar-frame x, y, z).
    velocity_m_s : (float, float, float) or None
        World-frame velocity (m/s): the target starts where it is at ping 0 and goes straight.
    backscatter : object
        Its backscatter model (``unit``, ``fixed``, ``rayleigh``, ``swimbladder``).
    random_phase : bool
    """

    frame: str
    position_m: tuple
    velocity_m_s: tuple | None
    backscatter: object
    random_phase: bool = False


@dataclass(frozen=True, eq=False)
class Targets:
    """A scene's point targets, resolved for the ping loop (acoustics/simulation/setup.py).

    Attributes
    ----------
    points : tuple of TargetPoint
    populations : tuple
        The populations as validated (uniform cuboid or sector, school): their law of number,
        place, backscatter and swimming.
    interval_s : float
        Ping interval (s): ping p is at t = p x interval_s.
    pose0 : Pose
        The sonar's world pose at ping 0 (t = 0): where moving targets given relative to the
        sonar start from.
    wavenumber_rad_m : float
        k = 2π f0 / c (rad/m) of the carrier, for swimbladder echoes.
    seed : int
        The scene's seed (the default of :func:`draw_targets`).
    """

    points: tuple = ()
    populations: tuple = ()
    interval_s: float = 1.0
    pose0: Pose | None = None
    wavenumber_rad_m: float = 0.0
    seed: int = 0

@dataclass(frozen=True, eq=False)
class TargetSet:
    """The point targets of one ping, one row each.

    Attributes
    ----------
    position_sonar_m : ndarray, shape (n, 3)
        Sonar-frame positions (m).
    position_world_m : ndarray, shape (n, 3)
        World-frame positions (m).
    rho_m : ndarray, shape (n,)
        Backscatter amplitude ρ = √σ_bs (m).
    phase_rad : ndarray, shape (n,)
        Extra echo phase (rad); 0 unless the target asks for a random phase.
    group : ndarray of int, shape (n,)
        -1 for explicit points, else the index of the population.
    target_id : ndarray of int, shape (n,), optional
        Identity: explicit point i is i; fish k of population j is (j + 1) x 10⁶ + k. Persistent
        from ping to ping for points and for populations with ``redraw: false``.
    velocity_world_m_s : ndarray, shape (n, 3), optional
        World-frame velocity (m/s); zeros for targets that hold their place.
    shadowed : ndarray of bool, shape (n,), optional
        A mesh blocks the direct path.
    """

    position_sonar_m: np.ndarray
    position_world_m: np.ndarray
    rho_m: np.ndarray
    phase_rad: np.ndarray
    group: np.ndarray
    target_id: np.ndarray | None = None
    velocity_world_m_s: np.ndarray | None = None
    shadowed: np.ndarray | None = None
    """Whether a mesh blocks the target's direct path (set by the simulation; None before)."""

    def __len__(self) -> int:
        return int(self.rho_m.shape[0])

    @classmethod
    def empty(cls) -> "TargetSet":
        z = np.zeros((0, 3))
        return cls(z, z.copy(), np.zeros(0), np.zeros(0), np.zeros(0, int), np.zeros(0, np.int64),
                   z.copy())


def point_positions_sonar(points, pose: Pose) -> np.ndarray:
    """Sonar-frame positions (m), shape (n, 3), of explicit points for a sonar at ``pose``:
    :class:`TargetPoint` or point-target specs (whose ⟨r, θ, φ⟩ is converted here)."""
    out = np.zeros((len(points), 3))
    for i, t in enumerate(points):
        if t.position_m is None:
            out[i] = spherical_to_cartesian(t.range_m, t.azimuth, t.elevation)
        elif t.frame == "sonar":
            out[i] = t.position_m
        else:
            out[i] = pose.to_sonar(np.asarray(t.position_m, float))
    return out


def draw_backscatter(model, n: int, rng: np.random.Generator) -> np.ndarray:
    """ρ (m) for ``n`` targets of one backscatter model, shape (n,)."""
    if model.model == "unit":
        return np.ones(n)
    if model.model == "fixed":
        return np.full(n, 10.0 ** (model.ts_db / 20.0))
    if model.model == "swimbladder":
        return np.ones(n)   # set from the bladder once positions are known (swimbladder_backscatter)
    s, lo, hi = model.scale_m, model.lo_m, model.hi_m
    # Rayleigh CDF F(x) = 1 - exp(-x²/2s²); sample F uniformly between F(lo) and F(hi)
    f_lo = -np.expm1(-lo * lo / (2 * s * s))
    f_hi = -np.expm1(-hi * hi / (2 * s * s))
    u = f_lo + (f_hi - f_lo) * rng.random(n)
    rho = s * np.sqrt(-2.0 * np.log1p(-u))
    return np.clip(rho, lo, hi)  # only rounding can leave [lo, hi]


def _population_positions(pop, n: int, rng: np.random.Generator, pose: Pose):
    """(sonar-frame, world-frame) positions of ``n`` targets of a population."""
    if pop.kind == "school":
        from acoustics.targets.schools import draw_school
        pw = draw_school(pop, n, rng)
        return pose.to_sonar(pw), pw
    if pop.kind == "uniform_cuboid":
        lo = np.array([pop.x_m[0], pop.y_m[0], pop.z_m[0]])
        hi = np.array([pop.x_m[1], pop.y_m[1], pop.z_m[1]])
        p = lo + (hi - lo) * rng.random((n, 3))
        if pop.frame == "world":
            return pose.to_sonar(p), p
        return p, pose.to_world(p)
    (r0, r1), (a0, a1), (e0, e1) = pop.range_m, pop.azimuth, pop.elevation
    u = rng.random((n, 3))
    r = np.cbrt(r0**3 + u[:, 0] * (r1**3 - r0**3))       # uniform in volume: dV ∝ r² dr
    th = a0 + u[:, 1] * (a1 - a0)
    ph = np.arcsin(np.sin(e0) + u[:, 2] * (np.sin(e1) - np.sin(e0)))  # dV ∝ cos φ dφ
    p = spherical_to_cartesian(r, th, ph)
    return p, pose.to_world(p)


#: population j's fish k has identity (j + 1) x ID_BLOCK + k
ID_BLOCK = 1_000_000


def draw_targets(spec: Targets, ping: int, pose: Pose, *, seed: int | None = None,
                 swimbladders: bool = True) -> TargetSet:
    """All point targets of one ping.

    Parameters
    ----------
    spec : Targets
        The scene's targets, resolved (``setup.targets``).
    ping : int
        Ping index (the seed's second component; the time t = ping x ``pings.interval_s`` of
        moving targets).
    pose : Pose
        The sonar's pose at this ping (for frame conversions).
    seed : int, optional
        Overrides ``spec.seed``.
    swimbladders : bool
        Give fish with a swimbladder model their echo (:func:`swimbladder_backscatter`); false
        leaves their ρ = 1 for the caller to time that stage apart.

    Returns
    -------
    TargetSet
    """
    from acoustics.targets.motion import swim_trajectory
    seed = spec.seed if seed is None else int(seed)
    t = ping * spec.interval_s
    parts_w, parts_s, vels, rhos, phases, groups, ids = [], [], [], [], [], [], []
    if spec.points:
        ps = point_positions_sonar(spec.points, pose)
        pw = pose.to_world(ps)
        v = np.zeros((len(spec.points), 3))
        moving = [i for i, tp in enumerate(spec.points) if tp.velocity_m_s is not None]
        if moving:
            # a moving point starts where it is at ping 0 (in the ping-0 pose's world) and goes
            # straight: x(t) = x(0) + v t
            p0 = spec.pose0
            for i in moving:
                v[i] = spec.points[i].velocity_m_s
                pw[i] = p0.to_world(point_positions_sonar([spec.points[i]], p0))[0] + v[i] * t
            ps = pose.to_sonar(pw)
        parts_s.append(ps)
        parts_w.append(pw)
        vels.append(v)
        rng_b = ping_rng(seed, ping, "backscatter", 0)
        rng_p = ping_rng(seed, ping, "phase", 0)
        rho = np.array([draw_backscatter(tp.backscatter, 1, rng_b)[0] for tp in spec.points])
        ph = rng_p.uniform(-np.pi, np.pi, len(spec.points))
        ph = np.where([tp.random_phase for tp in spec.points], ph, 0.0)
        rhos.append(rho)
        phases.append(ph)
        groups.append(np.full(len(spec.points), -1))
        ids.append(np.arange(len(spec.points), dtype=np.int64))
    for j, pop in enumerate(spec.populations, start=1):
        pos_ping = ping if pop.redraw else FIXED
        if pop.count is not None:
            n = pop.count
        else:
            n = int(ping_rng(seed, pos_ping, "count", j).poisson(pop.density_per_m3 * pop.volume_m3))
        ps, pw = _population_positions(pop, n, ping_rng(seed, pos_ping, "positions", j), pose)
        v = np.zeros((n, 3))
        if pop.swim is not None:
            if pop.kind != "school" and getattr(pop, "frame", "world") != "world":
                # start from the ping-0 world positions (a sonar-frame region at the mount pose)
                pw = spec.pose0.to_world(ps)
            pw, v = swim_trajectory(pop.swim, pw, seed=seed, group=j,
                                    interval_s=spec.interval_s, ping=ping)
            ps = pose.to_sonar(pw)
        parts_s.append(ps)
        parts_w.append(pw)
        vels.append(v)
        rhos.append(draw_backscatter(pop.backscatter, n, ping_rng(seed, ping, "backscatter", j)))
        ph = ping_rng(seed, ping, "phase", j).uniform(-np.pi, np.pi, n)
        phases.append(ph if pop.random_phase else np.zeros(n))
        groups.append(np.full(n, j - 1))
        ids.append(j * ID_BLOCK + np.arange(n, dtype=np.int64))
    if not parts_s:
        return TargetSet.empty()
    out = TargetSet(np.concatenate(parts_s), np.concatenate(parts_w), np.concatenate(rhos),
                    np.concatenate(phases), np.concatenate(groups).astype(int),
                    np.concatenate(ids), np.concatenate(vels))
    return swimbladder_backscatter(spec, out, ping, pose, seed) if swimbladders else out


def has_swimbladders(spec: Targets) -> bool:
    """Whether any point target or population has a swimbladder backscatter model."""
    return any(t.backscatter.model == "swimbladder" for t in (*spec.points, *spec.populations))


def swimbladder_backscatter(spec: Targets, targets: TargetSet, ping: int, pose: Pose,
                            seed: int) -> TargetSet:
    """The targets with ρ and phase of those whose backscatter model is a swimbladder set from
    their bladder at this ping's incidence angle (acoustics/targets/fish.py); the others as they
    were.

    Each fish's heading is its swimming direction, else a uniform draw (once for the run when
    the fish keep their identities, every ping when a population is redrawn); its tilt is drawn
    every ping from N(``tilt_mean_deg``, ``tilt_sd_deg``), stream ``tilt`` (group 0: the
    explicit points; j: population j), plus the climb angle of its path when it swims up or
    down.

    Parameters
    ----------
    spec : Targets
        The scene's targets, resolved (``setup.targets``).
    targets : TargetSet
        As :func:`draw_targets` gives them with ``swimbladders=False``.
    ping, seed : int
    pose : Pose
        The sonar's pose at this ping: its origin is the transmitter.
    """
    if not has_swimbladders(spec) or len(targets) == 0:
        return targets
    from acoustics.targets.fish import fish_amplitude
    k = spec.wavenumber_rad_m
    rho, phase = targets.rho_m.copy(), targets.phase_rad.copy()
    v = (targets.velocity_world_m_s if targets.velocity_world_m_s is not None
         else np.zeros((len(targets), 3)))
    # (rows of the target set, their backscatter model per row, stream group, redrawn each ping)
    groups = []
    fish_points = [i for i, tp in enumerate(spec.points) if tp.backscatter.model == "swimbladder"]
    if fish_points:
        groups.append((np.flatnonzero(targets.group == -1)[fish_points],
                       [spec.points[i].backscatter for i in fish_points], 0, False))
    for g, pop in enumerate(spec.populations):
        if pop.backscatter.model == "swimbladder":
            idx = np.flatnonzero(targets.group == g)
            groups.append((idx, [pop.backscatter] * idx.size, g + 1, pop.redraw))
    for idx, models, stream_group, redrawn in groups:
        if idx.size == 0:
            continue
        rng = ping_rng(seed, ping, "tilt", stream_group)
        z = rng.standard_normal(idx.size)
        own = (rng if redrawn else ping_rng(seed, FIXED, "tilt", stream_group)).uniform(
            -np.pi, np.pi, idx.size)
        swimming = np.hypot(v[idx, 0], v[idx, 1]) > 0
        heading = np.where(swimming, np.arctan2(v[idx, 1], v[idx, 0]), own)
        mean = np.array([m.tilt_mean for m in models])
        sd = np.array([m.tilt_sd for m in models])
        # a fish rising or sinking as it swims points its nose along its path (z is down)
        climb = np.where(swimming, np.arctan2(-v[idx, 2], np.hypot(v[idx, 0], v[idx, 1])), 0.0)
        tilt = mean + sd * z + climb
        # one table look-up per distinct bladder (a population has one; points may differ)
        for model in {id(m): m for m in models}.values():
            sel = np.array([m is model for m in models])
            f, _ = fish_amplitude(model, targets.position_world_m[idx[sel]], pose.position_m,
                                  heading[sel], tilt[sel], k)
            rho[idx[sel]] = np.abs(f)
            phase[idx[sel]] = phase[idx[sel]] + np.angle(f)
    return replace(targets, rho_m=rho, phase_rad=phase)
