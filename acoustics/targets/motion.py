"""Targets that move between pings: straight lines, and swimming with turns.

A moving target's position at ping p is a deterministic function of (scene seed, its population,
its index, t_p = p x interval): the initial state (speed, heading, vertical speed) is drawn once
(ping index :data:`~acoustics.seeds.FIXED`), and the heading's random walk is one seeded stream
of increments, step after step, whose first k steps are the same however many are drawn. So any
ping can be simulated alone (an experiment's worker) and gives the same fish where a full run
puts them; trajectories are cached per process so a run of P pings costs O(P), not O(P²).

Integration: the velocity is constant within a step of dt = interval / ``substeps`` and the
position is its exact integral; headings turn between steps by N(0, σ_turn² dt). Vertical motion
is reflected at the sea surface (z = 0), so swimming fish stay in the water.
"""
from __future__ import annotations

import numpy as np

from acoustics.seeds import FIXED, ping_rng, stream_seed

__all__ = ["polarisation_kappa", "swim_start", "swim_trajectory", "SwimTrack"]

_TRACKS: dict = {}


def polarisation_kappa(polarisation: float) -> float:
    """Von Mises concentration κ whose mean resultant length I1(κ)/I0(κ) equals ``polarisation``
    (0 → 0, uniform headings; 1 → inf, all parallel)."""
    from scipy.optimize import brentq
    from scipy.special import i0e, i1e
    r = float(polarisation)
    if r <= 0:
        return 0.0
    if r >= 1:
        return np.inf
    return float(brentq(lambda k: i1e(k) / i0e(k) - r, 1e-9, 1e7, xtol=1e-12))


def swim_start(swim, n: int, rng: np.random.Generator):
    """Initial speed (m/s), heading (rad) and vertical speed (m/s) of ``n`` swimmers, each
    shape (n,)."""
    speed = np.abs(swim.speed_m_s + swim.speed_sd_m_s * rng.standard_normal(n))
    kappa = polarisation_kappa(swim.polarisation)
    if np.isinf(kappa):
        heading = np.full(n, float(swim.heading))
    elif kappa == 0.0:
        heading = rng.uniform(-np.pi, np.pi, n)
    else:
        heading = swim.heading + rng.vonmises(0.0, kappa, n)
    vz = swim.vertical_sd_m_s * rng.standard_normal(n)
    return speed, heading, vz


class SwimTrack:
    """Positions and velocities of one population's swimmers at the ping times 0..P."""

    def __init__(self, start_m, speed, heading, vz, *, turn_sd_rad_per_s, interval_s, substeps,
                 turn_rng_seed):
        self.start_m = np.asarray(start_m, float)
        self.speed, self.heading0, self.vz = speed, heading, vz
        self.turn_sd = float(turn_sd_rad_per_s)
        self.dt = float(interval_s) / int(substeps)
        self.substeps = int(substeps)
        self.seed = turn_rng_seed
        self.positions = self.start_m[None]                                # (P+1, n, 3)
        self.velocities = self._velocity(self.heading0)[None]

    def _velocity(self, heading):
        return np.stack([self.speed * np.cos(heading), self.speed * np.sin(heading), self.vz], -1)

    def extend(self, pings: int):
        """Compute the track out to ping ``pings`` (and a margin), from ping 0 again."""
        if pings < len(self.positions):
            return
        total = max(pings, 2 * (len(self.positions) - 1), 8)
        n = len(self.start_m)
        steps = total * self.substeps
        if self.turn_sd > 0 and n:
            rng = np.random.default_rng(self.seed)
            turns = self.turn_sd * np.sqrt(self.dt) * rng.standard_normal((steps, n))
            heading = self.heading0 + np.vstack([np.zeros((1, n)), np.cumsum(turns, axis=0)])
        else:
            heading = np.broadcast_to(self.heading0, (steps + 1, n))
        vel = np.stack([self.speed * np.cos(heading), self.speed * np.sin(heading),
                        np.broadcast_to(self.vz, heading.shape)], -1)            # (steps+1, n, 3)
        raw = self.start_m + np.vstack([np.zeros((1, n, 3)), np.cumsum(vel[:-1] * self.dt, axis=0)])
        pos = raw.copy()
        above = raw[..., 2] < 0
        pos[..., 2] = np.abs(raw[..., 2])              # reflected at the surface: fish stay wet
        vel[..., 2] = np.where(above, -vel[..., 2], vel[..., 2])
        self.positions = pos[::self.substeps]
        self.velocities = vel[::self.substeps]

    def at(self, ping: int):
        """(positions (n, 3), velocities (n, 3)) at ping ``ping`` (m, m/s; world frame)."""
        self.extend(ping)
        return self.positions[ping], self.velocities[ping]


def swim_trajectory(swim, start_m, *, seed: int, group: int, interval_s: float, ping: int):
    """World positions (m) and velocities (m/s) of a population's swimmers at ping ``ping``,
    each shape (n, 3); cached per (seed, group, start)."""
    start_m = np.asarray(start_m, float)
    key = (int(seed), int(group), start_m.tobytes(), swim.model_dump_json(), float(interval_s))
    track = _TRACKS.get(key)
    if track is None:
        rng = ping_rng(seed, FIXED, "motion", group)
        speed, heading, vz = swim_start(swim, len(start_m), rng)
        track = SwimTrack(start_m, speed, heading, vz, turn_sd_rad_per_s=swim.turn_sd,
                          interval_s=interval_s, substeps=swim.substeps,
                          turn_rng_seed=stream_seed(seed, FIXED, "turns", group))
        if len(_TRACKS) > 16:
            _TRACKS.clear()
        _TRACKS[key] = track
    return track.at(int(ping))
