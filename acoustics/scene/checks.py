"""Physics that is legal but surprising in a scene: warnings, never errors."""
from __future__ import annotations

import math

import numpy as np

from acoustics.scene.targets_spec import SchoolPopulation, SectorPopulation

__all__ = ["cross_check", "school_optical_depth", "SINGLE_SCATTERING_DEPTH"]

#: optical depth n σ_e L through a school beyond which single scattering no longer holds
#: (docs/scenes.md, "Single scattering and dense schools")
SINGLE_SCATTERING_DEPTH = 0.1


def _extinction_cross_section_m2(backscatter) -> float:
    """A target's extinction cross-section σ_e (m²): a swimbladder (pressure-release prolate
    spheroid, k b ≫ 1) removes twice its largest shadow, 2 π a b (the extinction paradox of a
    large obstacle, Morse & Ingard 1968, §8.3); a point reflector of backscattering cross-section
    σ_bs scattering isotropically removes σ_s = 4π σ_bs."""
    model = backscatter.model
    if model == "swimbladder":
        return 2.0 * math.pi * (backscatter.length_m / 2) * (backscatter.width_m / 2)
    if model == "unit":
        sigma_bs = 1.0
    elif model == "fixed":
        sigma_bs = 10.0 ** (backscatter.ts_db / 10.0)
    else:      # Rayleigh amplitude of scale s: E[ρ²] = 2 s² (untruncated), bounded by hi²
        sigma_bs = min(2.0 * backscatter.scale_m ** 2, backscatter.hi_m ** 2)
    return 4.0 * math.pi * sigma_bs


def school_optical_depth(pop, sonar_position_m) -> tuple[float, float, float, float]:
    """Optical depth τ = n σ_e L of a school along the sonar's line of sight to its centre.

    Parameters
    ----------
    pop : SchoolPopulation
    sonar_position_m : sequence of 3 floats
        The sonar's position (m, world frame).

    Returns
    -------
    tau, density_per_m3, sigma_e_m2, chord_m : float
        τ (dimensionless), the number density n (m⁻³), the extinction cross-section σ_e (m²) and
        the chord L (m) of the school's ellipsoid through its centre along the line of sight.
    """
    n = pop.count / pop.volume_m3 if pop.count is not None else pop.density_per_m3
    u = np.asarray(pop.center_m, float) - np.asarray(sonar_position_m, float)
    norm = float(np.linalg.norm(u))
    u = u / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
    h = math.radians(pop.heading)
    axes = np.array([[math.cos(h), math.sin(h), 0.0], [-math.sin(h), math.cos(h), 0.0], [0.0, 0.0, 1.0]])
    # chord through the centre of x²/a² + y²/b² + z²/c² = 1 along u: 2 / |u / semi-axes|
    chord = 2.0 / float(np.linalg.norm((axes @ u) / np.asarray(pop.semi_axes_m, float)))
    sigma_e = _extinction_cross_section_m2(pop.backscatter)
    return n * sigma_e * chord, n, sigma_e, chord


def cross_check(scene, *, notes: list | None = None) -> list[tuple[str, str]]:
    """Physics that is legal but surprising: (message, key path) pairs.

    ``notes``, if given, receives the (message, key path) pairs that describe what the ABACUS
    preset does by design (its grating lobes): worth saying once, not a warning."""
    notes = [] if notes is None else notes
    from acoustics.sonar.build import build_sonar
    from acoustics.targets.draw import point_positions_sonar
    out = []
    lam = scene.wavelength_m
    sonar = build_sonar(scene)
    rx = sonar.receiver
    pitches: dict[float, list[str]] = {}
    for group, idx in rx.image_groups.items():
        x = np.sort(rx.elements.center_m[idx, 0])
        if x.size > 1:
            pitches.setdefault(round(float(np.min(np.diff(x))), 12), []).append(group)
    for pitch, groups in pitches.items():
        if pitch > lam / 2:
            gl = math.degrees(math.asin(min(1.0, lam / pitch)))
            note = (f"receiver pitch {pitch * 1e3:.4g} mm exceeds λ/2 = {lam / 2 * 1e3:.4g} mm: "
                    f"grating lobes at ±{gl:.2f}° in image{'s' if len(groups) > 1 else ''} "
                    f"{' and '.join(groups)} (ABACUS has them on purpose; scan within "
                    f"±{gl / 2:.2f}°)", "sonar")
            # the preset's grating lobes are its design, not a surprise: a note for `scene
            # check`, not a warning repeated by every command
            (notes if scene.sonar.preset == "abacus" else out).append(note)
    out += list(scene.physics_notes)
    fs, band = scene.sampling.rate_hz, scene.signal.bandwidth_hz
    if fs < band:
        out.append((f"rate {fs:g} Hz is below the pulse bandwidth {band:g} Hz: even complex "
                    f"sampling aliases the echo", "sampling.rate_hz"))
    elif fs < 2 * band:
        out.append((f"rate {fs:g} Hz is below 2B = {2 * band:g} Hz: the real bandpass-sampled "
                    f"system would alias (this complex-baseband simulation does not)",
                    "sampling.rate_hz"))
    if scene.sampling.receiver_bandwidth_hz < band:
        out.append((f"receiver band {scene.sampling.receiver_bandwidth_hz:g} Hz is narrower than "
                    f"the pulse bandwidth {band:g} Hz", "sampling.receiver_bandwidth_hz"))
    c = scene.medium.sound_speed_m_s
    blind = c * scene.signal.duration_s / 2
    t_end = scene.sampling.time_offset_s + scene.sampling.samples / fs
    r_max = c * (t_end - scene.signal.duration_s) / 2
    r_first = c * scene.sampling.time_offset_s / 2
    for i, t in enumerate(scene.targets.points):
        pos = point_positions_sonar([t], sonar.pose)[0]
        r = float(np.linalg.norm(pos))
        key = f"targets.points[{i}]"
        if r < max(blind, r_first):
            out.append((f"target at {r:.3g} m is inside the blind zone (< {max(blind, r_first):.3g} m "
                        f"while transmitting or before recording starts)", key))
        elif r > r_max:
            out.append((f"target at {r:.3g} m is beyond the last range whose whole echo is "
                        f"recorded ({r_max:.3g} m)", key))
    for i, p in enumerate(scene.targets.populations):
        if isinstance(p, SchoolPopulation):
            tau, n, sig, chord = school_optical_depth(p, scene.sonar.pose.position_m)
            if tau > SINGLE_SCATTERING_DEPTH:
                name = f"'{p.label}'" if p.label else f"{i}"
                out.append((f"school {name} is too dense for single scattering: {n:.3g} fish/m³ × "
                            f"extinction cross-section {sig:.2g} m² × {chord:.3g} m through it = "
                            f"{tau:.2g} > {SINGLE_SCATTERING_DEPTH:g}, so its far side's echo loses "
                            f"{20 * math.log10(math.e) * tau:.1f} dB two-way and multiple scattering, "
                            f"which abacus leaves out, is of that order (docs/scenes.md)",
                            f"targets.populations[{i}]"))
        if isinstance(p, SectorPopulation) and p.range_m[0] < blind:
            out.append((f"population reaches into the blind zone (< {blind:.3g} m)",
                        f"targets.populations[{i}].range_m"))
    return out


def physical_problems(scene, *, notes: list | None = None) -> list[tuple[str, str]]:
    """What no sea allows: (message, key path) pairs that make a scene an error.

    Targets must be in the water — below the sea surface (world z = 0; z is depth) and above a
    flat or rough sea floor when the scene has one — and so must the sonar. Populations are
    checked over their whole region. Other meshes (rocks, files) are not checked: a target inside
    a rock is legal geometry (it is shadowed).

    Under a moving sea (``wind_sea``, ``swell``) the surface is the sea's own height at every
    ping of the run (``pings.first`` to ``first + count - 1``), not z = 0: the sonar (at its pose
    of each ping when the platform moves) and every target must stay below it at every ping, and
    above the sea floor its ``water_depth_m`` puts under the mean level. A target that a trough
    would leave in the air for one ping is refused: no sea holds water over it then.

    ``notes``, if given, receives (message, key path) pairs of what could not be checked (a run
    too long for the per-ping check's budget): :func:`cross_check` warns of them.
    """
    notes = [] if notes is None else notes
    from acoustics.sonar.build import build_sonar
    from acoustics.targets.draw import point_positions_sonar
    pose = build_sonar(scene).pose
    out = []
    seas = [(i, b) for i, b in enumerate(scene.boundaries)
            if b.mesh.shape in ("wind_sea", "swell") and b.role == "surface"]
    if pose.position_m[2] < -1e-9 and not seas:
        out.append((f"the sonar is {-pose.position_m[2]:.3g} m above the sea surface (world z = 0 "
                    f"is the surface, z is depth)", "sonar.pose.position_m"))
    floors = [_floor_depth(b) for b in scene.boundaries if b.role == "floor"]
    floors = [f for f in floors if f is not None]

    def check(points_world, key, what):
        z = points_world[:, 2]
        if z.size and z.min() < -1e-9 and not seas:
            out.append((f"{what} reaches {-z.min():.3g} m above the sea surface (world z = 0 is "
                        f"the surface, z is depth): targets must be in the water", key))
        for depth in floors:
            below = z - depth(points_world[:, 0], points_world[:, 1])
            if below.size and below.max() > 1e-9:
                out.append((f"{what} reaches {below.max():.3g} m below the sea floor: targets must "
                            f"be in the water", key))
                break

    pings = _Pings(scene)
    motion = _platform_motion(scene)
    if motion is not None and not seas:
        # the platform's worst heave and roll over the run must keep the sonar wet
        worst = (np.inf, 0.0)
        for t in pings.blocks():
            z = motion.poses(pose, t)[0][:, 2]
            j = int(np.argmin(z))
            worst = min(worst, (float(z[j]), float(t[j])))
        if worst[0] < -1e-9:
            out.append((f"the platform's motion lifts the sonar {-worst[0]:.3g} m above the sea "
                        f"surface at t = {worst[1]:.3g} s (world z = 0 is the surface, z "
                        f"is depth): mount it deeper or move it less", "sonar.motion"))
    last_t = pings.last * scene.pings.interval_s
    if scene.targets.points:
        world = pose.to_world(point_positions_sonar(scene.targets.points, pose))
        for i, p in enumerate(world):
            check(p[None, :], f"targets.points[{i}]", f"the target at depth {p[2]:.3g} m")
            v = scene.targets.points[i].velocity_m_s
            if v is not None and last_t > 0:   # a straight line: its ends are its extremes
                end = p + np.asarray(v, float) * last_t
                check(end[None, :], f"targets.points[{i}].velocity_m_s",
                      f"the moving target at the last ping (t = {last_t:.3g} s, depth {end[2]:.3g} m)")
    for i, pop in enumerate(scene.targets.populations):
        check(_region_samples(pop, pose), f"targets.populations[{i}]", "the population's region")
    for i, boundary in seas:
        out += _sea_problems(scene, i, boundary, pose, motion, pings, notes)
    return out


class _Pings:
    """The pings of a run (``pings.first`` to ``first + count - 1``) and their times (s after
    ping 0), in blocks (a run may hold ten million pings)."""

    BLOCK = 65536

    def __init__(self, scene):
        self.first, self.count = scene.pings.first, scene.pings.count
        self.interval = scene.pings.interval_s
        self.last = self.first + self.count - 1

    def blocks(self, start: int = 0, stop: int | None = None, size: int | None = None):
        """Times (s) of the pings first + start .. first + stop - 1, a block at a time."""
        stop = self.count if stop is None else stop
        size = size or self.BLOCK
        for lo in range(start, stop, size):
            yield (self.first + np.arange(lo, min(lo + size, stop))) * self.interval


def _platform_motion(scene):
    """The platform's :class:`~acoustics.sonar.platform.PlatformMotion`, or None (it is still, or
    its motion file cannot be read: loading the scene reports that file)."""
    if scene.sonar.motion is None:
        return None
    from acoustics.sonar.platform import PlatformMotion
    from processing.base.config import ConfigError
    try:
        return PlatformMotion.from_spec(scene.sonar.motion, scene.resolve_path)
    except (ConfigError, OSError, ValueError):
        return None


#: what the per-ping sea check may spend, in evaluations of one wave component at one point and
#: one ping made by matrix products (~10⁸–10⁹ a second; at a point that moves, one at a time, each
#: counts MOVING_COST): a run longer than this allows is checked over its first pings, and
#: :func:`cross_check` says so
SEA_CHECK_BUDGET = 1e8
MOVING_COST = 50


def _sea_bodies(scene, pose, motion, pings):
    """What must stay under a moving sea: (key, what, fixed world points (n, 3) or None,
    a function of ping times giving world points (T, n, 3) or None)."""
    from acoustics.targets.draw import point_positions_sonar
    out = []
    if motion is None:
        out.append(("sonar.pose.position_m", "the sonar", pose.position_m[None, :], None))
    else:
        out.append(("sonar.motion", "the sonar (moved by the platform's motion)", None,
                    lambda t: motion.poses(pose, t)[0][:, None, :]))

    def riding(points_sonar):
        """Sonar-frame points at each ping's pose of a moving platform."""
        def at(t):
            position, rot = motion.poses(pose, t)
            return position[:, None, :] + np.einsum("tij,nj->tni", rot, points_sonar)
        return at

    p0 = pose
    if motion is not None:
        from acoustics.frames import Pose
        position, rot = motion.poses(pose, np.zeros(1))
        p0 = Pose(position[0], rot[0])
    for i, tp in enumerate(scene.targets.points):
        key = f"targets.points[{i}]"
        if tp.velocity_m_s is not None:
            start = p0.to_world(point_positions_sonar([tp], p0))[0]
            v = np.asarray(tp.velocity_m_s, float)
            out.append((f"{key}.velocity_m_s", "the moving target", None,
                        lambda t, start=start, v=v: (start + t[:, None] * v)[:, None, :]))
        elif tp.frame == "world" or motion is None:
            out.append((key, "the target", pose.to_world(point_positions_sonar([tp], pose)), None))
        else:
            out.append((key, "the target (riding with the sonar)", None,
                        riding(point_positions_sonar([tp], pose))))
    for i, pop in enumerate(scene.targets.populations):
        key = f"targets.populations[{i}]"
        sonar_frame = pop.kind == "uniform_sector" or (pop.kind == "uniform_cuboid"
                                                        and pop.frame == "sonar")
        world = _region_samples(pop, pose)
        if sonar_frame and motion is not None and pop.swim is None:
            out.append((key, "the population's region (riding with the sonar)", None,
                        riding(pose.to_sonar(world))))
        else:
            out.append((key, "the population's region", world, None))
    return out


def _sea_problems(scene, index: int, boundary, pose, motion, pings, notes) -> list[tuple[str, str]]:
    """The sonar and targets against one moving sea at every ping (see
    :func:`physical_problems`): (message, key path) pairs, one per thing that leaves the water.

    The sea's height comes from its own function of (x, y, t) (no mesh); points the sea's reach
    Σ|a| cannot touch are passed without evaluating it. A run too long for the budget
    (:data:`SEA_CHECK_BUDGET`) is checked over its first pings and the rest goes to ``notes``."""
    from acoustics.paths.sea_surface import surface_of
    spec = boundary.mesh
    mkey = f"boundaries[{index}].mesh"
    name = f"the {spec.shape.replace('_', ' ')} ({boundary.name!r})"
    surf = surface_of(spec, scene.seed)
    tr = spec.transform
    from acoustics.frames import transform_rotation
    rot = transform_rotation(tr.rotate_deg)
    down = float(rot[2, 2])       # world z of the sea's own z axis (its "down")
    if abs(down) < 1e-6:
        return []                  # a sea stood on its edge: no "above" to test
    sign = 1.0 if down > 0 else -1.0
    level, reach, tol = spec.mean_level_m, surf.reach_m, 1e-9
    safe = level + sign * reach
    n_comp = max(surf.amplitude_m.size, 1)

    def local(points):
        """World points (..., 3) in the sea's own frame (before its transform)."""
        shifted = np.asarray(points, float) - np.asarray(tr.translate_m)
        return np.einsum("ji,...j->...i", rot, shifted) / tr.scale

    out = []
    fixed, moving = [], []       # what the sea may reach: (key, what, points)
    for key, what, points, path in _sea_bodies(scene, pose, motion, pings):
        if points is None:
            moving.append((key, what, path))
            continue
        q = local(points)
        below = sign * (q[:, 2] - level)          # depth under the still level, sea units
        if key == "sonar.pose.position_m" and below.min() < -tol:
            if level == 0.0:    # the still level where the world puts it: the sonar is misplaced
                out.append((f"the sonar is {-below.min() * tr.scale:.3g} m above the still surface "
                            f"of {name} (z = 0 m, z is depth): it must be in the water, below "
                            f"z = {safe:.3g} m to stay there at every ping", key))
            else:
                out.append((f"{name} has its still surface at z = {level:g} m (mean_level_m), "
                            f"{-below.min() * tr.scale:.3g} m below the sonar (z = "
                            f"{points[0, 2]:.3g} m): the sonar would be in the air; mean_level_m "
                            f"must be less than the sonar's z, {points[0, 2]:.3g} m (z is depth)",
                            f"{mkey}.mean_level_m"))
            continue
        problem = _below_floor(below, spec.water_depth_m, tr.scale, what, name)
        if problem:
            out.append((problem, key))
        elif below.min() <= reach + tol:            # else deeper than any trough
            fixed.append((key, what, q[below <= reach + tol]))
    if not fixed and not moving:
        return out
    sizes = [len(path(pings.first * pings.interval + np.zeros(1))[0]) for _, _, path in moving]
    per_ping = (sum(len(q) for _, _, q in fixed) + MOVING_COST * sum(sizes)) * n_comp
    affordable = int(min(pings.count, SEA_CHECK_BUDGET // max(per_ping, 1)))
    if affordable < pings.count:
        done = (f"pings {pings.first}–{pings.first + affordable - 1} only" if affordable
                else "no ping")
        notes.append((f"{name}: the sonar and targets were checked against its moving surface at "
                      f"{done} of {pings.first}–{pings.last} (the check's budget, "
                      f"{pings.count * per_ping:.2g} evaluations); later pings are not known to "
                      f"keep them in the water", mkey))
    block = max(1, int(min(_Pings.BLOCK, 2e6 // max(per_ping / n_comp, 1))))
    t_sea = spec.time_offset_s
    for key, what, q in fixed:
        for t in pings.blocks(stop=affordable, size=block):
            eta = surf.elevation_series(q[:, 0], q[:, 1], t_sea + t)       # (n, T)
            gap = sign * (q[:, 2:3] - (level - eta))    # depth under the moving surface
            if gap.min() < -tol:
                k = int(np.unravel_index(int(np.argmin(gap)), gap.shape)[1])
                out.append((_exposed(what, name, -gap.min() * tr.scale, t[k], pings, safe,
                                     tr.scale), key))
                break
        else:
            high = -float(np.min(sign * (q[:, 2] - level)))
            if high > tol and affordable == pings.count:
                # legal (a crest over it at every ping of the run) but not what a sea holds
                notes.append((f"{what} is {high * tr.scale:.3g} m above the still level of {name} "
                              f"(mean_level_m) and in the water only because every ping of the "
                              f"run finds a crest over it; another ping interval would not", key))
    for (key, what, path), n in zip(moving, sizes):
        for t in pings.blocks(stop=affordable, size=max(1, block // max(n, 1))):
            pts = local(path(t))                           # (T, n, 3)
            below = sign * (pts[..., 2] - level)
            problem = _below_floor(below, spec.water_depth_m, tr.scale, what, name, t, pings)
            if problem:
                out.append((problem, key))
                break
            near = below <= reach + tol
            if not near.any():
                continue
            tt = np.broadcast_to((t_sea + t)[:, None], near.shape)[near]
            gap = np.full(near.shape, np.inf)
            gap[near] = sign * (pts[..., 2][near] - (level - surf.elevation_at(
                pts[..., 0][near], pts[..., 1][near], tt)))
            if gap.min() < -tol:
                k = int(np.unravel_index(int(np.argmin(gap)), gap.shape)[0])
                out.append((_exposed(what, name, -gap.min() * tr.scale, t[k], pings, safe,
                                     tr.scale), key))
                break
    return out




def _below_floor(below, depth, scale, what, name, t=None, pings=None):
    """The message when points lie deeper than the sea's water_depth_m puts its floor, or None."""
    if depth is None or below.max() <= depth + 1e-9:
        return None
    where = ""
    if t is not None:
        k = int(np.unravel_index(int(np.argmax(below)), below.shape)[0])
        where = f" at ping {int(round(t[k] / pings.interval))}"
    return (f"{what} lies {(below.max() - depth) * scale:.3g} m below the sea floor{where} that "
            f"{name} puts {depth * scale:g} m under its mean level (water_depth_m): at most "
            f"{depth * scale:g} m deep, or a larger water_depth_m")


def _exposed(what, name, height, t, pings, safe, scale):
    """The message when a point is above the moving surface at a ping."""
    ping = int(round(t / pings.interval))
    sea = "the sea's frame, " if scale != 1.0 else ""
    return (f"{what} is {height:.3g} m above the surface of {name} at ping {ping} (t = {t:.4g} s): "
            f"it must stay in the water at every ping (any depth below z = {safe:.3g} m, "
            f"{sea}mean_level_m + the sea's reach Σ amplitude, always does)")


def _floor_depth(boundary):
    """Depth of a flat or rough floor as a function of world (x, y), or None (other shapes or
    frames)."""
    shape = boundary.mesh
    if boundary.frame != "world" or any(shape.transform.rotate_deg) or shape.transform.scale != 1.0:
        return None
    dz = shape.transform.translate_m[2]
    if shape.shape == "plane":
        n = np.asarray(shape.normal, float)
        if abs(n[2]) < 0.999 * np.linalg.norm(n):
            return None   # a tilted plane: not a floor we can read a depth off
        return lambda x, y: np.full(np.shape(x), shape.center_m[2] + dz)
    if shape.shape == "rough_floor":
        sx, sy = shape.slope
        cx, cy = shape.center_m
        # the height field's deepest excursion is bounded by 4 RMS (Gaussian field)
        return lambda x, y: (shape.depth_m + dz + sx * (np.asarray(x) - cx) + sy * (np.asarray(y) - cy)
                             + 4.0 * shape.rms_height_m)
    return None


def _region_samples(pop, pose) -> np.ndarray:
    """World points on the boundary of a population's region (corners and edge samples)."""
    g = np.linspace(0.0, 1.0, 5)
    if pop.kind == "uniform_cuboid":
        (x0, x1), (y0, y1), (z0, z1) = pop.x_m, pop.y_m, pop.z_m
        X, Y, Z = np.meshgrid(x0 + g * (x1 - x0), y0 + g * (y1 - y0), z0 + g * (z1 - z0), indexing="ij")
        pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], -1)
        return pts if pop.frame == "world" else pose.to_world(pts)
    from acoustics.frames import spherical_to_cartesian
    if pop.kind == "school":
        from acoustics.targets.schools import ellipsoid_axes
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 13), np.linspace(-np.pi / 2, np.pi / 2, 7))
        unit = np.stack([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)], -1).reshape(-1, 3)
        return np.asarray(pop.center_m) + (unit * np.asarray(pop.semi_axes_m)) @ ellipsoid_axes(pop.heading).T
    (r0, r1), (a0, a1), (e0, e1) = pop.range_m, pop.azimuth, pop.elevation
    R, A, E = np.meshgrid(r0 + g * (r1 - r0), a0 + g * (a1 - a0), e0 + g * (e1 - e0), indexing="ij")
    return pose.to_world(spherical_to_cartesian(R.ravel(), A.ravel(), E.ravel()))
