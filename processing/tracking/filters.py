"""Fish tracks across pings: a tracker built of replaceable parts, over 3-D detections.

The thesis counts per ping and names tracking (an αβ tracker) as its next step (§7). Here a
detection is a point located in the world frame (range, azimuth and interferometric elevation
through its ping's pose, so the platform's motion is removed) with a covariance from its own
uncertainty (:func:`measurement_covariance`). The tracker is made of parts, in the shape of
Stone Soup (predictor/updater, hypothesiser/data associator, initiator/deleter) without its
framework, each chosen by a setting of ``track`` and tested on its own:

* **motion** (:mod:`processing.tracking.motion`, ``method``): constant-velocity Kalman filter
  with RTS smoothing, or the thesis' αβ filter;
* **gate and assign** (:mod:`processing.tracking.association`, ``association``): a chi-square
  gate of ``gate_probability`` on the innovation's Mahalanobis distance, then global nearest
  neighbour (Hungarian algorithm on d² + ln|S|) or the parametric JPDA, which shares a
  detection that falls in several gates;
* **track management** (:mod:`processing.tracking.management`): M-of-N confirmation
  (``confirm_hits`` of ``confirm_window``), deletion after ``max_misses`` consecutive misses,
  births from the detections no track takes.
* **track splitting** (:mod:`processing.tracking.splitting`, ``split``): once tracking ends, a
  confirmed track whose detections step back through the fan's thin dimension against its own
  motion through it (a second fish entering behind the first, one echo to the gate) is cut there.

Ping by ping: every live track predicts its state to the ping's time; detections are gated and
assigned; assigned tracks update, the others coast; unassigned detections start tentative tracks;
management confirms, drops and ends tracks. Confirmed tracks are split, then smoothed (RTS for the Kalman
filter; the αβ tracker's positions are its filtered ones). Pure functions over arrays and a
small :class:`Track` record; no state outside a call, so the result depends only on the
detections and the settings.

Why not a library: Stone Soup (the most complete, maintained tracking framework) represents every
state, detection and hypothesis as a Python object with a dozen dependencies, and filterpy has
not been released since 2018; what is needed here is a constant-velocity predict/update (ten
lines of linear algebra, tested against the closed-form steady state) and an optimal assignment,
which scipy provides. The scoring, where re-deriving is error-prone, uses py-motmetrics
(processing/tracking/scores.py) and is checked against trackeval (processing/tracking/hota.py).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from processing.tracking.association import (gate_threshold, gated_costs, global_nearest_neighbour,
                                             jpda_weights)
from processing.tracking.management import MOfN
from processing.tracking.motion import cv_matrices, motion_model
from processing.tracking.splitting import NoSplit

__all__ = ["Track", "track_detections", "measurement_covariance", "resolution_covariance", "fan_normal",
           "cv_matrices"]


@dataclass
class Track:
    """One track: the detections it holds and its states.

    Attributes
    ----------
    track_id : int
    pings : list of int
        Ping index of every ping from its birth to its last update.
    detection : list of int
        Row of the detection table assigned at each of those pings, −1 for a miss.
    x, P : list of ndarray
        Filtered state (6,) [x, y, z, vx, vy, vz] (m, m/s, world frame) and covariance (6, 6)
        after each ping's update (or prediction, on a miss).
    x_pred, P_pred : list of ndarray
        The predictions those came from (for the smoother).
    times : list of float
        Time (s) of each of those pings.
    confirmed : bool
    hits : int
    misses : int
        Consecutive misses at the end.
    smoothed : list of ndarray
        Smoothed states (6,), one per ping, once the track is finished (RTS for the Kalman
        filter, the filtered states for αβ).
    R : list of ndarray or None
        Measurement covariance (3, 3) its update used at each ping, None for a miss.
    """

    track_id: int
    pings: list = field(default_factory=list)
    detection: list = field(default_factory=list)
    x: list = field(default_factory=list)
    P: list = field(default_factory=list)
    x_pred: list = field(default_factory=list)
    P_pred: list = field(default_factory=list)
    times: list = field(default_factory=list)
    confirmed: bool = False
    hits: int = 0
    misses: int = 0
    shadowed: int = 0
    smoothed: list = field(default_factory=list)
    R: list = field(default_factory=list)


def measurement_covariance(range_m, azimuth_rad, elevation_rad, snr_db, *, range_resolution_m: float,
                           azimuth_resolution_rad: float, wavelength_m: float, baseline_m: float,
                           interference_db: float = 30.0, rotation=None):
    """World-frame covariance of located detections, from their own uncertainty.

    Range and azimuth: a peak of resolution δ measured at a signal-to-noise ratio SNR has
    σ = δ / √(2 SNR) (the Cramér–Rao bound of a peak's position, Skolnik 2008, §2.12).
    Elevation: the interferometric phase of two channels has σ_ψ = 1/√SNR (rad), so
    σ_φ = σ_ψ λ / (2π b cos φ). A strong echo is not limited by the noise but by the echoes it
    overlaps (a neighbour's sidelobes, an unresolved neighbour, its own range sidelobes), so SNR
    is replaced by the signal-to-interference-plus-noise ratio 1/(1/SNR + 1/SIR), SIR =
    ``interference_db``. Measured on the school_tracks scene (docs/validation.md, "Tracking"):
    matched detections above 60 dB SNR are mostly within 1 cm of their fish but a tail (merged
    echoes) is off by 5–10 cm; at SIR = 20 dB the 99 % gate holds 91–93 % of them, at 30 dB
    65–75 %. The spherical covariance is carried to Cartesian by the Jacobian of
    x = r cos φ sin θ, y = r sin φ, z = r cos φ cos θ and rotated to the world by the ping's
    ``rotation``.

    Parameters
    ----------
    range_m, azimuth_rad, elevation_rad, snr_db : array_like, shape (n,)
        snr_db NaN (no noise estimate) is taken as 20 dB.
    range_resolution_m, azimuth_resolution_rad, wavelength_m, baseline_m : float
    interference_db : float
        Signal-to-interference ratio (dB) that caps the effective SNR of strong echoes.
    rotation : ndarray, shape (3, 3) or (n, 3, 3), optional
        Sonar axes in world coordinates (columns); None: identity.

    Returns
    -------
    ndarray, shape (n, 3, 3)
        Covariance (m²).
    """
    r = np.asarray(range_m, float)
    th = np.asarray(azimuth_rad, float)
    ph = np.asarray(elevation_rad, float)
    snr = 10.0 ** (np.nan_to_num(np.asarray(snr_db, float), nan=20.0) / 10.0)
    snr = np.maximum(snr, 1.0)
    # what limits a strong echo is not the noise but the echoes it overlaps (neighbours'
    # sidelobes, its own range sidelobes): the ratio of signal to noise plus interference
    sinr = 1.0 / (1.0 / snr + 10.0 ** (-float(interference_db) / 10.0))
    s_r = range_resolution_m / np.sqrt(2 * sinr)
    s_t = azimuth_resolution_rad / np.sqrt(2 * sinr)
    s_p = wavelength_m / (2 * np.pi * baseline_m * np.maximum(np.cos(ph), 1e-3)) / np.sqrt(sinr)
    return _to_world(r, th, ph, s_r, s_t, s_p, rotation)


def resolution_covariance(range_m, azimuth_rad, elevation_rad, *, range_resolution_m: float,
                          azimuth_resolution_rad: float, elevation_resolution_rad: float, rotation=None):
    """World-frame covariance of a position anywhere within a resolution cell (σ = δ/√12 per axis).

    Two fish closer than a resolution cell (range resolution × azimuth resolution × the
    transmitter's elevation beamwidth, which mixes every echo of the fan's thickness) give one
    echo, placed anywhere between them, or two that swap; an echo within a cell of a track's
    prediction is therefore no evidence of a new fish. The tracker's resolution gate
    (``track.resolution_cells``) uses this covariance.

    Parameters
    ----------
    range_m, azimuth_rad, elevation_rad : array_like, shape (n,)
    range_resolution_m, azimuth_resolution_rad, elevation_resolution_rad : float
        3 dB widths of the cell.
    rotation : ndarray, shape (3, 3) or (n, 3, 3), optional
        Sonar axes in world coordinates (columns); None: identity.

    Returns
    -------
    ndarray, shape (n, 3, 3)
        Covariance (m²).
    """
    r = np.asarray(range_m, float)
    th = np.asarray(azimuth_rad, float)
    ph = np.asarray(elevation_rad, float)
    one = np.ones_like(r)
    # an unresolved echo lies anywhere within its cell: uniform, σ = δ/√12
    u = one / np.sqrt(12.0)
    return _to_world(r, th, ph, range_resolution_m * u, azimuth_resolution_rad * u,
                     elevation_resolution_rad * u, rotation)


def _to_world(r, th, ph, s_r, s_t, s_p, rotation):
    """Spherical standard deviations (range m, azimuth rad, elevation rad) of points at
    (r, θ, φ) as world-frame covariances (n, 3, 3): the Jacobian of x = r cos φ sin θ,
    y = r sin φ, z = r cos φ cos θ, then the ping's rotation."""
    ct, st, cp, sp = np.cos(th), np.sin(th), np.cos(ph), np.sin(ph)
    J = np.empty(r.shape + (3, 3))
    J[..., 0, :] = np.stack([cp * st, r * cp * ct, -r * sp * st], -1)
    J[..., 1, :] = np.stack([sp, np.zeros_like(r), r * cp], -1)
    J[..., 2, :] = np.stack([cp * ct, -r * cp * st, -r * sp * ct], -1)
    S = np.zeros(r.shape + (3, 3))
    S[..., 0, 0], S[..., 1, 1], S[..., 2, 2] = s_r**2, s_t**2, s_p**2
    C = J @ S @ np.swapaxes(J, -1, -2)
    if rotation is not None:
        R = np.asarray(rotation, float)
        C = R @ C @ np.swapaxes(R, -1, -2)
    return C


def track_detections(ping_index, time_s, position_m, covariance_m2, *, method: str = "kalman",
                     association: str = "gnn", gate_probability: float = 0.99,
                     accel_sd_m_s2: float = 0.5, initial_speed_sd_m_s: float = 1.0, alpha: float = 0.5,
                     beta: float = 0.2, confirm_hits: int = 3, confirm_window: int = 4,
                     max_misses: int = 2, resolution_m2=None, resolution_cells: float = 1.0,
                     confirm_resolved: bool = False, motion=None, management=None, through_fan=None,
                     fan_width_m=None, fan_centre_m=None, split=None):
    """Tracks of detections across pings.

    Parameters
    ----------
    ping_index : array_like of int, shape (n,)
        Ping of each detection.
    time_s : mapping or array_like
        Time (s) of each ping: ``time_s[p]`` for every ping p in ``ping_index`` (an array indexed
        by ping index, or a dict).
    position_m : array_like, shape (n, 3)
        World positions (m).
    covariance_m2 : array_like, shape (n, 3, 3)
        Their covariances (:func:`measurement_covariance`).
    method : {"kalman", "alpha_beta"}
        The motion part (:func:`processing.tracking.motion.motion_model`), unless ``motion``
        gives one.
    association : {"gnn", "jpda"}
        The gate-and-assign part (:mod:`processing.tracking.association`).
    gate_probability, accel_sd_m_s2, initial_speed_sd_m_s, alpha, beta, confirm_hits,
    confirm_window, max_misses
        See the module docstring.
    resolution_m2 : array_like, shape (n, 3, 3), optional
        Each detection's resolution cell as a covariance (:func:`resolution_covariance`).
        With it, the resolution gate: a track left without a detection by the assignment takes
        an unassigned detection within ``resolution_cells`` cells of its prediction (Mahalanobis
        distance against P + R + c² C_cell inside the same chi-square gate; its update then
        uses R + c² C_cell, as the echo may be merged with a neighbour's), and a detection no
        track took but lying within that gate of a confirmed track starts no new track — the sonar
        cannot tell a new fish from the tracked one there (an echo merged with or split from a
        neighbour's). The price: a fish that stays within a cell of a tracked one starts its
        own track only once they part.
    resolution_cells : float
        c above; 0 turns the resolution gate off.
    confirm_resolved : bool
        With the resolution gate: a tentative track's hit counts towards its confirmation only
        when its detection lies outside the resolution gate of every senior track (confirmed, or
        holding more hits, or as many and born first) that took a detection at the same ping —
        the resolution gate's rule for births applied through the confirmation window, where
        two peaks of one echo, or one fish's echo merged with its neighbour's, would otherwise
        confirm two tracks born together (at the first pings, before any track is confirmed).
    motion : object, optional
        A motion part (``predict``, ``innovation_covariance``, ``update``, ``update_mixture``,
        ``smooth``; :mod:`processing.tracking.motion`) used instead of ``method``.
    management : MOfN, optional
        The track-management part used instead of ``confirm_hits``, ``confirm_window``,
        ``max_misses`` and ``initial_speed_sd_m_s``.
    through_fan : array_like, shape (n, 3), optional
        Each detection's direction through the fan (unit vector of increasing elevation, world
        frame; :func:`fan_normal`): what the splitting part reads a track's motion through the
        fan along. None: no splitting.
    fan_width_m : array_like, shape (n,) or scalar, optional
        The fan's thickness at each detection's range (m: range × the transmitter's elevation
        beamwidth); needed when ``split`` and ``through_fan`` are given.
    fan_centre_m : array_like, shape (n,) or scalar, optional
        n·p, the sonar's position p along ``through_fan`` at each detection's ping (m), so that
        u = n·z − n·p is 0 on the fan's centre plane; None: 0 (the sonar at the origin).
    split : object, optional
        The track-splitting part (``breaks(time_s, through_fan_m, variance_m2, fan_width_m)``;
        :mod:`processing.tracking.splitting`), applied to every confirmed track once tracking
        ends: each part it cuts becomes a track of its own, its states filtered again from its
        first detection (born as management births a track, then the motion part's updates with
        the covariances the track used). None: no splitting.

    Returns
    -------
    list of Track
        Confirmed tracks, ordered by birth (then by the detection that started them); each with
        ``smoothed`` states (list of (6,) arrays), one per ping of the track.
    """
    if association not in ("gnn", "jpda"):
        raise ValueError(f"tracking association must be 'gnn' or 'jpda', got {association!r}")
    if motion is None:
        motion = motion_model(method, accel_sd_m_s2=accel_sd_m_s2, alpha=alpha, beta=beta,
                              speed_sd_m_s=initial_speed_sd_m_s)
    if management is None:
        management = MOfN(confirm_hits, confirm_window, max_misses, initial_speed_sd_m_s)
    pings = np.asarray(ping_index, int).ravel()
    pos = np.asarray(position_m, float).reshape(-1, 3)
    cov = np.asarray(covariance_m2, float).reshape(-1, 3, 3)
    if not (len(pings) == len(pos) == len(cov)):
        raise ValueError("ping_index, position_m and covariance_m2 must have one row per detection")
    ok = np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(cov), axis=(1, 2))
    cell = None
    if resolution_m2 is not None and resolution_cells > 0:
        cell = float(resolution_cells) ** 2 * np.asarray(resolution_m2, float).reshape(-1, 3, 3)
        if len(cell) != len(pos):
            raise ValueError("resolution_m2 must have one row per detection")
        ok &= np.all(np.isfinite(cell), axis=(1, 2))
    gate = gate_threshold(float(gate_probability))
    live: list[Track] = []
    done: list[Track] = []
    next_id = 0
    # every ping, those without detections too: a track misses there
    order = sorted(time_s) if isinstance(time_s, dict) else range(len(time_s))
    for p in order:
        t = float(time_s[p])
        rows = np.flatnonzero((pings == p) & ok)
        # 1. predict every live track to this ping
        pred = []
        for tr in live:
            dt = t - tr.times[-1]
            xp, Pp = motion.predict(tr.x[-1], tr.P[-1], dt)
            pred.append((xp, Pp, dt))
        # 2. gate and assign
        if live and rows.size:
            S = np.stack([motion.innovation_covariance(Pp, cov[rows], dt) for xp, Pp, dt in pred])
            S = np.broadcast_to(S, (len(live), rows.size, 3, 3))
            _, cost = gated_costs(np.array([xp[:3] for xp, _, _ in pred]), S, pos[rows], gate)
        else:
            cost = np.full((len(live), rows.size), np.inf)
        a_tr, a_det = global_nearest_neighbour(cost)
        assigned = dict(zip(a_tr.tolist(), a_det.tolist()))
        used = set(a_det.tolist())
        blocked = set()
        loose = {}
        shadow = set()
        if cell is not None and live and rows.size:
            # the resolution gate: a second, looser pass over what the first left, and no
            # births within a cell of a live track
            S2 = np.stack([motion.innovation_covariance(Pp, cov[rows] + cell[rows], dt) for _, Pp, dt in pred])
            S2 = np.broadcast_to(S2, (len(live), rows.size, 3, 3))
            _, cost2 = gated_costs(np.array([xp[:3] for xp, _, _ in pred]), S2, pos[rows], gate)
            free_t = np.array([i for i in range(len(live)) if i not in assigned], int)
            free_d = np.array([k for k in range(rows.size) if k not in used], int)
            if free_t.size and free_d.size:
                b_tr, b_det = global_nearest_neighbour(cost2[np.ix_(free_t, free_d)])
                for i, k in zip(free_t[b_tr].tolist(), free_d[b_det].tolist()):
                    assigned[i] = k
                    loose[i] = k
                    used.add(k)
            firm = np.array([tr.confirmed for tr in live], bool)
            blocked = set(np.flatnonzero(np.isfinite(cost2[firm]).any(axis=0)).tolist()) - used
            if confirm_resolved:
                def senior(l, i):
                    a_, b_ = live[l], live[i]
                    return a_.confirmed or a_.hits > b_.hits or (a_.hits == b_.hits and a_.track_id < b_.track_id)
                for i, k in assigned.items():
                    if live[i].confirmed:
                        continue
                    if any(np.isfinite(cost2[l, k]) for l in assigned if l != i and senior(l, i)):
                        shadow.add(i)
        weights = jpda_weights(cost) if association == "jpda" and cost.size else None
        # 3. update
        for i, (tr, (xp, Pp, dt)) in enumerate(zip(live, pred)):
            tr.pings.append(int(p))
            tr.times.append(t)
            tr.x_pred.append(xp)
            tr.P_pred.append(Pp)
            shared = weights is not None and np.count_nonzero(weights[i]) > 1
            if shared:
                k = np.flatnonzero(weights[i] > 0)
                x, P = motion.update_mixture(xp, Pp, pos[rows[k]], cov[rows[k]], weights[i, k], dt)
            if i in assigned:
                j = rows[assigned[i]]
                if i in loose:
                    x, P = motion.update(xp, Pp, pos[j], cov[j] + cell[j], dt)
                elif not shared:
                    x, P = motion.update(xp, Pp, pos[j], cov[j], dt)
                tr.x.append(x)
                tr.P.append(P)
                tr.R.append(cov[j] + cell[j] if i in loose else cov[j])
                tr.detection.append(int(j))
                tr.hits += 1
                tr.shadowed += i in shadow
                tr.misses = 0
            else:
                tr.x.append(x if shared else xp)
                tr.P.append(P if shared else Pp)
                tr.detection.append(-1)
                tr.R.append(None)
                tr.misses += 1
            if not tr.confirmed and management.confirmed(tr.hits - tr.shadowed, len(tr.pings)):
                tr.confirmed = True
        # 4. births, deaths
        still = []
        for tr in live:
            hopeless = not tr.confirmed and management.hopeless(tr.hits - tr.shadowed, len(tr.pings))
            if management.ended(tr.misses) or hopeless:
                if tr.confirmed:
                    done.append(tr)
            else:
                still.append(tr)
        live = still
        for k, j in enumerate(rows):
            if k in used or k in blocked:
                continue
            x0, P0 = management.birth(pos[j], cov[j])
            tr = Track(next_id, [int(p)], [int(j)], [x0], [P0], [x0], [P0], [t], hits=1, R=[cov[j]])
            tr.confirmed = management.confirmed(1, 1)
            next_id += 1
            live.append(tr)
    done.extend(tr for tr in live if tr.confirmed)
    for tr in done:
        _trim(tr)
    if split is not None and not isinstance(split, NoSplit) and through_fan is not None:
        normal = np.asarray(through_fan, float).reshape(-1, 3)
        if len(normal) != len(pos):
            raise ValueError("through_fan must have one row per detection")
        if fan_width_m is None:
            raise ValueError("splitting tracks needs fan_width_m (the fan's thickness at each detection)")
        width = np.broadcast_to(np.asarray(fan_width_m, float), (len(pos),))
        centre = np.zeros(len(pos)) if fan_centre_m is None else np.broadcast_to(
            np.asarray(fan_centre_m, float), (len(pos),))
        parts = []
        for tr in done:
            pieces = _split(tr, split, normal, centre, width, pos, motion, management, next_id)
            next_id += len(pieces) - 1
            parts.extend(pieces)
        done = parts
    for tr in done:
        tr.smoothed = motion.smooth(tr.x, tr.P, tr.x_pred, tr.P_pred, tr.times)
    done.sort(key=lambda tr: (tr.pings[0], tr.track_id))
    for new_id, tr in enumerate(done):
        tr.track_id = new_id
    return done


def fan_normal(n: int, rotation=None):
    """The direction through the fan at each of ``n`` detections: the sonar's elevation axis
    (its y axis, towards which elevation increases at broadside) in world coordinates, so that
    u = n·z is a detection's position across the fan's thin dimension, r sin φ up to the
    sonar's own position.

    Parameters
    ----------
    n : int
        Number of detections.
    rotation : ndarray, shape (3, 3) or (n, 3, 3), optional
        Sonar axes in world coordinates (columns) at each detection's ping; None: identity.

    Returns
    -------
    ndarray, shape (n, 3)
        Unit vectors (world frame).
    """
    if rotation is None:
        return np.tile([0.0, 1.0, 0.0], (int(n), 1))
    R = np.asarray(rotation, float)
    return np.broadcast_to(R[..., :, 1], (int(n), 3)).copy()


def _split(tr: Track, split, normal, centre, width, pos, motion, management, next_id):
    """``tr`` cut where ``split`` finds a second fish: the first part keeps its states (the
    filter is causal), each later part is filtered again from its first detection; the later
    parts take ids from ``next_id`` on."""
    at = [i for i, j in enumerate(tr.detection) if j >= 0]
    if len(at) < 2:
        return [tr]
    det = np.array([tr.detection[i] for i in at], int)
    n = normal[det]
    u = np.einsum("ki,ki->k", n, pos[det]) - centre[det]
    var = np.einsum("ki,kij,kj->k", n, np.array([tr.R[i] for i in at]), n)
    cuts = split.breaks(np.array([tr.times[i] for i in at]), u, var, width[det])
    if not cuts:
        return [tr]
    starts = [at[c] for c in cuts]
    bounds = [0] + starts + [len(tr.pings)]
    first = Track(tr.track_id, confirmed=True)
    for name in ("pings", "detection", "x", "P", "x_pred", "P_pred", "times", "R"):
        setattr(first, name, getattr(tr, name)[:starts[0]])
    _trim(first)
    out = [first]
    for k, (a, b) in enumerate(zip(bounds[1:-1], bounds[2:])):
        j0 = tr.detection[a]
        x, P = management.birth(pos[j0], tr.R[a])
        part = Track(next_id + k, [tr.pings[a]], [j0], [x], [P], [x], [P], [tr.times[a]], confirmed=True,
                     R=[tr.R[a]])
        for i in range(a + 1, b):
            dt = tr.times[i] - part.times[-1]
            xp, Pp = motion.predict(part.x[-1], part.P[-1], dt)
            j = tr.detection[i]
            if j >= 0:
                x, P = motion.update(xp, Pp, pos[j], tr.R[i], dt)
            else:
                x, P = xp, Pp
            for name, val in (("pings", tr.pings[i]), ("detection", j), ("x", x), ("P", P), ("x_pred", xp),
                              ("P_pred", Pp), ("times", tr.times[i]), ("R", tr.R[i])):
                getattr(part, name).append(val)
        _trim(part)
        out.append(part)
    for part in out:
        part.hits = sum(j >= 0 for j in part.detection)
    return out


def _trim(tr: Track):
    """Drop the trailing misses: a track ends at its last detection."""
    while tr.detection and tr.detection[-1] < 0:
        for name in ("pings", "detection", "x", "P", "x_pred", "P_pred", "times", "R"):
            getattr(tr, name).pop()

