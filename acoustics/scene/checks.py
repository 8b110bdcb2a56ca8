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
