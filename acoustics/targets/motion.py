"""Targets that move between pings: straight lines, and swimming with turns.

A moving target's position at ping p is a deterministic function of (scene seed, its population,
its index, t_p = p x interval): the initial state (speed, heading, vertical speed) is drawn once
(ping index :data:`~acoustics.seeds.FIXED`), and the heading's random walk is one seeded stream
of increments, step after step, whose first k steps are the same however many are drawn. So any
ping can be simulated alone (an experiment's worker) and gives the same fish where a full run
puts them; trajectories are cached per process and extended block by block, so a run of P
pings costs O(P), not O(P²).

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
    """Positions and velocities of one population's swimmers at the ping times 0, 1, 2, ...

    Computed in blocks of :attr:`BLOCK` pings aligned on multiples of it, each continuing the
    last (heading, unreflected position and the turn stream's generator), so the numbers at a
    ping do not depend on which pings were asked for first, and memory holds one block's
    sub-steps at a time.
    """

    BLOCK = 16

    def __init__(self, start_m, speed, heading, vz, *, turn_sd_rad_per_s, interval_s, substeps,
                 turn_rng_seed, turn_together: bool = False):
        import threading
        self.start_m = np.asarray(start_m, float).reshape(-1, 3)
        self.speed, self.heading0, self.vz = (np.asarray(a, float) for a in (speed, heading, vz))
        self.turn_sd = float(turn_sd_rad_per_s)
        self.substeps = int(substeps)
        self.dt = float(interval_s) / self.substeps
        self._rng = np.random.default_rng(turn_rng_seed) if self.turn_sd > 0 else None
        self.turn_together = bool(turn_together)
        self._heading = self.heading0.copy()          # at the last ping computed
        self._raw = self.start_m.copy()                # unreflected position there
        self._positions = [_reflect(self.start_m)[None]]
        self._velocities = [_reflect_velocity(self._velocity(self.heading0), self.start_m)[None]]
        self._done = 0                                 # last ping computed
        self._lock = threading.Lock()

    def _velocity(self, heading):
        return np.stack([self.speed * np.cos(heading), self.speed * np.sin(heading),
                         np.broadcast_to(self.vz, np.shape(heading))], -1)

    def extend(self, pings: int):
        """Compute the track out to ping ``pings`` (whole blocks)."""
        with self._lock:
            while self._done < pings:
                self._block()

    def _block(self):
        n, k = len(self.start_m), self.substeps
        steps = self.BLOCK * k
        if self._rng is not None and n:
            width = 1 if self.turn_together else n      # one walk for all, or one each
            turns = self.turn_sd * np.sqrt(self.dt) * self._rng.standard_normal((steps, width))
            heading = self._heading + np.vstack([np.zeros((1, width)), np.cumsum(turns, axis=0)])
        else:
            heading = np.broadcast_to(self._heading, (steps + 1, n))
        vel = self._velocity(heading)                                      # (steps+1, n, 3)
        raw = self._raw + np.vstack([np.zeros((1, n, 3)), np.cumsum(vel[:-1] * self.dt, axis=0)])
        at = raw[k::k]                                                     # pings done+1 ...
        self._positions.append(_reflect(at))
        self._velocities.append(_reflect_velocity(vel[k::k], at))
        self._heading = np.array(heading[-1])
        self._raw = raw[-1].copy()
        self._done += self.BLOCK

    def at(self, ping: int):
        """(positions (n, 3), velocities (n, 3)) at ping ``ping`` (m, m/s; world frame)."""
        ping = int(ping)
        self.extend(ping)
        b, i = (0, 0) if ping == 0 else ((ping - 1) // self.BLOCK + 1, (ping - 1) % self.BLOCK)
        return self._positions[b][i], self._velocities[b][i]


def _reflect(raw_m):
    """Positions reflected at the sea surface (z = 0): fish stay in the water."""
    out = np.array(raw_m, float)
    out[..., 2] = np.abs(out[..., 2])
    return out


def _reflect_velocity(vel, raw_m):
    """Velocities of reflected positions: the vertical component turns where the unreflected
    path is above the surface."""
    out = np.array(vel, float)
    out[..., 2] = np.where(np.asarray(raw_m)[..., 2] < 0, -out[..., 2], out[..., 2])
    return out


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
                          turn_rng_seed=stream_seed(seed, FIXED, "turns", group),
                          turn_together=swim.turn_together)
        if len(_TRACKS) > 16:
            _TRACKS.clear()
        _TRACKS[key] = track
    return track.at(int(ping))
