"""Physics that is legal but surprising in a scene: warnings, never errors."""
from __future__ import annotations

import math

import numpy as np

from acoustics.scene.targets_spec import SectorPopulation

__all__ = ["cross_check"]


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
        if isinstance(p, SectorPopulation) and p.range_m[0] < blind:
            out.append((f"population reaches into the blind zone (< {blind:.3g} m)",
                        f"targets.populations[{i}].range_m"))
    return out


def physical_problems(scene) -> list[tuple[str, str]]:
    """What no sea allows: (message, key path) pairs that make a scene an error.

    Targets must be in the water — below the sea surface (world z = 0; z is depth) and above a
    flat or rough sea floor when the scene has one — and so must the sonar. Populations are
    checked over their whole region. Other meshes (rocks, files) are not checked: a target inside
    a rock is legal geometry (it is shadowed).
    """
    from acoustics.sonar.build import build_sonar
    from acoustics.targets.draw import point_positions_sonar
    pose = build_sonar(scene).pose
    out = []
    if pose.position_m[2] < -1e-9:
        out.append((f"the sonar is {-pose.position_m[2]:.3g} m above the sea surface (world z = 0 "
                    f"is the surface, z is depth)", "sonar.pose.position_m"))
    floors = [_floor_depth(b) for b in scene.boundaries if b.role == "floor"]
    floors = [f for f in floors if f is not None]

    def check(points_world, key, what):
        z = points_world[:, 2]
        if z.size and z.min() < -1e-9:
            out.append((f"{what} reaches {-z.min():.3g} m above the sea surface (world z = 0 is "
                        f"the surface, z is depth): targets must be in the water", key))
        for depth in floors:
            below = z - depth(points_world[:, 0], points_world[:, 1])
            if below.size and below.max() > 1e-9:
                out.append((f"{what} reaches {below.max():.3g} m below the sea floor: targets must "
                            f"be in the water", key))
                break

    last_t = (scene.pings.count - 1) * scene.pings.interval_s
    if scene.sonar.motion is not None and scene.sonar.motion.kind != "file":
        # the platform's worst heave and roll over the run must keep the sonar wet
        from acoustics.sonar.platform import PlatformMotion
        motion = PlatformMotion.from_spec(scene.sonar.motion, scene.resolve_path)
        t = np.arange(scene.pings.count) * scene.pings.interval_s
        z = motion.poses(pose, t)[0][:, 2]
        if z.min() < -1e-9:
            out.append((f"the platform's motion lifts the sonar {-z.min():.3g} m above the sea "
                        f"surface at t = {t[int(np.argmin(z))]:.3g} s (world z = 0 is the surface, z "
                        f"is depth): mount it deeper or move it less", "sonar.motion"))
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
    return out


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
