"""One ping: targets, paths, echoes, noise and ADC, each stage only when the scene needs it.

A ping reads the run's frozen :class:`~acoustics.simulation.setup.Setup` (the resolved scene) and
fills the run's :class:`~acoustics.simulation.setup.RunCache`; every path kind carries its own
rate of change of length (its Doppler) in its :class:`VirtualScatterers`.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from acoustics.seeds import ping_rng
from acoustics.simulation.arrival_table import arrival_table, direct_tags
from acoustics.simulation.setup import RunCache, Setup
from acoustics.simulation.stages import StageLog
from acoustics.synthesis.receiver import band_limited_noise, quantize
from acoustics.synthesis.scatterers import VirtualScatterers
from acoustics.synthesis.synthesize import synthesize
from acoustics.targets.draw import (TargetSet, draw_targets, has_swimbladders,
                                    swimbladder_backscatter)

__all__ = ["simulate_ping", "doppler_shift_hz", "direct_path_rate_m_s"]


def direct_path_rate_m_s(setup: Setup, ping: int, pose, targets: TargetSet) -> np.ndarray:
    """d(path length)/dt (m/s) of each target's direct two-way path, shape (n,): −2 v_r, v_r the
    speed at which target and sonar close (the target's velocity, less the sonar's, along the
    line between them; the sonar's from its poses 0.05 s either side of the ping)."""
    v_target = (targets.velocity_world_m_s if targets.velocity_world_m_s is not None
                else np.zeros((len(targets), 3)))
    v_sonar = _sonar_velocity_world(setup, ping)
    d = targets.position_world_m - pose.position_m
    dist = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.divide(d, dist, out=np.zeros_like(d), where=dist > 0)
    closing = -np.sum((v_target - v_sonar) * d, axis=1)
    return -2.0 * closing


def doppler_shift_hz(setup: Setup, ping: int, pose, targets: TargetSet) -> np.ndarray:
    """Two-way Doppler shift f_d = 2 v_r f0 / c (Hz) of each target's direct path, shape (n,)
    (:func:`direct_path_rate_m_s`: f_d = −f0 (dL/dt) / c)."""
    rate = direct_path_rate_m_s(setup, ping, pose, targets)
    return -rate * setup.center_frequency_hz / setup.medium.sound_speed_m_s


def _sonar_velocity_world(setup: Setup, ping: int) -> np.ndarray:
    """The sonar's world velocity (m/s) at a ping, from its poses 0.05 s either side."""
    if setup.platform is None:
        return np.zeros(3)
    dt = 0.05
    t = ping * setup.interval_s
    before = setup.platform.pose(setup.sonar.pose, t - dt).position_m
    after = setup.platform.pose(setup.sonar.pose, t + dt).position_m
    return (after - before) / (2 * dt)


def _with_shadow(targets: TargetSet, shadowed):
    """The target set with its shadowing recorded (ground truth)."""
    return replace(targets, shadowed=np.asarray(shadowed, bool))


def simulate_ping(setup: Setup, ping: int, *, cache: RunCache | None = None,
                  seed: int | None = None, log: StageLog | None = None,
                  arrivals: list | None = None):
    """One ping.

    ``setup`` is read, never changed; ``cache`` is the run's :class:`RunCache` (a fresh one,
    its ray caster built for this ping alone, when None). ``arrivals``: a list the ping's
    arrivals table (acoustics/simulation/arrival_table.py) is appended to when the scene
    records arrivals (``setup.effects.arrivals``); only then does the ``arrivals`` stage run.

    Returns
    -------
    samples : ndarray, shape (n_channels, n_samples), complex128
        ADC counts.
    clipped : ndarray of int, shape (n_channels,), or None
        Clipped samples per channel (None when the ADC does not quantise).
    targets : TargetSet
    """
    seed = setup.seed if seed is None else int(seed)
    log = log if log is not None else StageLog()
    cache = cache if cache is not None else RunCache(setup, log)
    s, fx = setup.sampling, setup.effects
    n_ch = setup.sonar.n_channels
    pose = setup.pose_at(ping)
    with log.stage("targets"):
        targets = draw_targets(setup.targets, ping, pose, seed=seed, swimbladders=False)
    if has_swimbladders(setup.targets) and len(targets):
        with log.stage("swimbladder_ts"):
            targets = swimbladder_backscatter(setup.targets, targets, ping, pose, seed)
    strength = targets.rho_m * np.exp(1j * targets.phase_rad)
    rs, view = cache.ray_scene_at(pose, log)
    if rs is not None and not rs.prepared:
        # once per run (a still floor's BVH, search blocks, the reverberation fan): set-up
        with log.stage("rays_build"):
            rs.prepare(setup, seed)
    scatters = fx.reverberation is not None
    mesh_targets = setup.rays is not None and setup.rays.has_mesh_targets
    if rs is not None and rs.moving and (scatters or mesh_targets or (
            len(targets) and (fx.occlusion or fx.max_bounces > 0))):
        with log.stage("sea_surface"):
            rs.advance(ping * setup.interval_s)
    shadowed = np.zeros(len(targets), bool)
    if rs is not None and fx.occlusion and len(targets):
        with log.stage("occlusion"):
            shadowed = rs.shadowed(targets.position_sonar_m, view)
    direct = ~shadowed
    p_rx = targets.position_sonar_m
    if not fx.stop_and_hop and setup.platform is not None and len(targets):
        with log.stage("platform_in_flight"):
            p_rx = setup.platform.at_arrival(setup.sonar.pose, ping * setup.interval_s,
                                             targets.position_world_m, setup.medium.sound_speed_m_s)
    # each path kind carries its own rate of change of length (its Doppler), when asked for
    direct_rate = None
    if fx.doppler and len(targets):
        with log.stage("doppler"):
            direct_rate = direct_path_rate_m_s(setup, ping, pose, targets)[direct]
    want = fx.arrivals
    parts = [VirtualScatterers(targets.position_sonar_m[direct], p_rx[direct],
                               strength[direct], np.full(int(direct.sum()), "direct"), direct_rate,
                               tags=direct_tags(np.flatnonzero(direct)) if want else None)]
    if rs is not None and fx.max_bounces > 0 and rs.reflectors and len(targets):
        with log.stage("multipath"):
            kw = {}
            if fx.doppler:   # the paths' rates of change of length, for their Doppler shifts
                v_t = (targets.velocity_world_m_s if targets.velocity_world_m_s is not None
                       else np.zeros((len(targets), 3)))
                kw = dict(velocities_m_s=v_t @ pose.rotation,
                          sonar_velocity_m_s=pose.rotation.T @ _sonar_velocity_world(setup, ping))
            parts.append(rs.multipath(targets.position_sonar_m, strength, fx.max_bounces, view,
                                      tags=want, **kw))
    if rs is not None and mesh_targets:
        with log.stage("mesh_targets"):
            parts.append(rs.mesh_targets(view))
    if rs is not None and scatters:
        with log.stage("reverberation"):
            parts.append(rs.reverberation(setup, ping, seed, view))
    vs = VirtualScatterers.concat(parts)
    # f_d = −f0 (dL/dt) / c of every path; boundary and mesh-target facets hold still (rate 0)
    doppler = vs.doppler_hz(setup.center_frequency_hz, setup.medium.sound_speed_m_s)
    if want:
        with log.stage("arrivals"):
            table = arrival_table(setup, ping, vs, _with_shadow(targets, shadowed),
                                  doppler, rs, view)
        if arrivals is not None:
            arrivals.append(table)
    if len(vs):
        with log.stage("echoes"):
            bistatic = not np.array_equal(vs.p_tx, vs.p_rx)
            x = synthesize(setup.model, vs.p_tx, vs.strength, pulse=setup.pulse,
                           rate_hz=s.rate_hz, n_samples=s.samples, t0_s=s.time_offset_s,
                           method=fx.synthesis, kernel_length=fx.kernel_length,
                           oversampling=fx.oversampling,
                           receive_positions_m=vs.p_rx if bistatic else None,
                           doppler_hz=doppler, doppler_bin_hz=fx.doppler_bin_hz,
                           doppler_method=fx.doppler_method, doppler_error_db=fx.doppler_error_db)
    else:
        x = np.zeros((n_ch, s.samples), complex)
    targets = _with_shadow(targets, shadowed)
    if setup.noise.sigma_counts > 0:
        with log.stage("noise"):
            x = x + band_limited_noise(ping_rng(seed, ping, "noise"), n_ch, s.samples,
                                       sigma_counts=setup.noise.sigma_counts,
                                       bandwidth_hz=setup.noise.bandwidth_hz, rate_hz=s.rate_hz)
    clipped = None
    if s.quantize:
        with log.stage("adc"):
            x, clipped = quantize(x, s.bits)
    return x, clipped, targets
