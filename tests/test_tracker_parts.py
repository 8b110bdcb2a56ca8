"""The tracker's parts on their own (processing/tracking/motion.py, association.py, management.py,
filters.py's resolution gate): each checked against a closed form or a case simple enough to
reason about, and each replaceable through the settings."""
from __future__ import annotations

import numpy as np
import pytest

from processing.tracking.association import (gate_threshold, gated_costs, global_nearest_neighbour,
                                             jpda_weights)
from processing.tracking.filters import resolution_covariance, track_detections
from processing.tracking.management import MOfN
from processing.tracking.motion import AlphaBeta, ConstantVelocityKalman, cv_matrices, motion_model


def _iso(n, sd_m):
    return np.repeat((sd_m**2 * np.eye(3))[None], n, axis=0)


def test_kalman_settles_to_the_riccati_steady_state():
    """After many pings the filter's predicted covariance and gain are those of the discrete
    algebraic Riccati equation for the same F, Q, H, R (solved independently by scipy): the
    steady-state αβ gains of the white-acceleration model (Bar-Shalom et al. 2001, §6.5)."""
    from scipy.linalg import solve_discrete_are
    T, s_m, a = 0.25, 0.02, 0.3
    f = ConstantVelocityKalman(a)
    x, P = np.zeros(6), np.diag([1, 1, 1, 4, 4, 4.0])
    R = s_m**2 * np.eye(3)
    for _ in range(400):
        xp, Pp = f.predict(x, P, T)
        x, P = f.update(xp, Pp, np.zeros(3), R, T)
    F = np.array([[1, T], [0, 1.0]])
    Q = a**2 * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
    H = np.array([[1.0, 0.0]])
    P_ss = solve_discrete_are(F.T, H.T, Q, np.array([[s_m**2]]))
    axis = np.ix_([0, 3], [0, 3])
    np.testing.assert_allclose(Pp[axis], P_ss, rtol=1e-9)
    K = Pp[:, :3] @ np.linalg.inv(Pp[:3, :3] + R)
    np.testing.assert_allclose([K[0, 0], K[3, 0]], (P_ss @ H.T / (P_ss[0, 0] + s_m**2)).ravel(), rtol=1e-9)


def test_alpha_beta_applies_its_fixed_gains():
    """One αβ update: position moves α of the innovation, velocity β/T of it."""
    f = AlphaBeta(alpha=0.4, beta=0.1, speed_sd_m_s=0.5)
    x = np.array([0, 0, 10.0, 1.0, 0, 0])
    xp, Pp = f.predict(x, np.eye(6), 0.5)
    np.testing.assert_allclose(xp, [0.5, 0, 10, 1, 0, 0])
    z = xp[:3] + np.array([0.2, -0.1, 0.0])
    xn, _ = f.update(xp, Pp, z, 0.01 * np.eye(3), 0.5)
    np.testing.assert_allclose(xn[:3] - xp[:3], 0.4 * np.array([0.2, -0.1, 0.0]))
    np.testing.assert_allclose(xn[3:] - xp[3:], 0.1 * np.array([0.2, -0.1, 0.0]) / 0.5)
    # its gate: 2R plus the spread of the allowed speed over the interval
    S = f.innovation_covariance(Pp, 0.01 * np.eye(3), 0.5)
    np.testing.assert_allclose(S, (0.02 + 0.25**2) * np.eye(3))


def test_process_noise_of_a_zero_interval_is_zero_and_motion_model_refuses_unknowns():
    F, Q = cv_matrices(0.0, 1.0)
    np.testing.assert_array_equal(F, np.eye(6))
    np.testing.assert_array_equal(Q, np.zeros((6, 6)))
    assert isinstance(motion_model("alpha_beta"), AlphaBeta)
    with pytest.raises(ValueError, match="kalman"):
        motion_model("particle")


def test_chi_square_gate_and_mahalanobis_costs():
    """The gate is the χ²₃ quantile (scipy's, whether tabulated or not); a detection at k σ
    along an axis has d² = k²; outside the gate the cost is inf."""
    from scipy.stats import chi2
    for p in (0.9, 0.99, 0.95, 0.975):
        assert gate_threshold(p) == pytest.approx(chi2.ppf(p, 3), rel=1e-12)
    S = np.broadcast_to(np.diag([0.01, 0.04, 0.09]), (1, 3, 3, 3))
    det = np.array([[0.2, 0, 0], [0, 0.2, 0], [0, 0, 1.5]])      # 2σ, 1σ, 5σ
    d2, cost = gated_costs(np.zeros((1, 3)), S, det, gate_threshold(0.99))
    np.testing.assert_allclose(d2[0, :2], [4.0, 1.0])
    assert np.isinf(d2[0, 2]) and np.isinf(cost[0, 2])
    np.testing.assert_allclose(cost[0, :2], d2[0, :2] + np.log(0.01 * 0.04 * 0.09))


def test_global_nearest_neighbour_minimises_the_total_not_each_row():
    """Track 0 is nearest to detection 0 but track 1 can only take detection 0: the global
    optimum gives 0 → 1 and 1 → 0; inf entries are never assigned."""
    cost = np.array([[1.0, 2.0], [1.5, np.inf]])
    r, c = global_nearest_neighbour(cost)
    assert dict(zip(r.tolist(), c.tolist())) == {0: 1, 1: 0}
    r, c = global_nearest_neighbour(np.full((2, 2), np.inf))
    assert r.size == c.size == 0
    assert global_nearest_neighbour(np.zeros((0, 3)))[0].size == 0


def test_jpda_shares_an_ambiguous_detection_and_not_a_clear_one():
    """Two tracks, one detection equidistant from both: it is shared equally, and by less than
    a detection one track has to itself (Fitzgerald's β_ij = G_ij / (T_i + D_j − G_ij + B));
    each track's weights sum to at most 1; nothing outside a gate gets weight."""
    w = jpda_weights(np.array([[1.0], [1.0]]), detection_probability=0.9, clutter=1e-6)
    assert w[0, 0] == pytest.approx(w[1, 0]) and w[0, 0] < 0.5 + 1e-9
    alone = jpda_weights(np.array([[1.0]]), detection_probability=0.9, clutter=1e-6)
    assert alone[0, 0] > 0.99
    w = jpda_weights(np.array([[1.0, 1.0], [1.0, np.inf]]), detection_probability=0.9, clutter=1e-6)
    assert w[1, 1] == 0.0 and np.all(w.sum(axis=1) <= 1 + 1e-12)
    assert w[0, 1] > w[0, 0]      # equally near, but detection 1 is track 0's alone
    assert np.all(jpda_weights(np.full((2, 2), np.inf)) == 0)


def test_m_of_n_confirmation_deletion_and_birth():
    m = MOfN(confirm_hits=3, confirm_window=4, max_misses=2, initial_speed_sd_m_s=0.5)
    assert not m.confirmed(2, 3) and m.confirmed(3, 3) and m.confirmed(3, 4) and not m.confirmed(3, 5)
    assert m.hopeless(1, 4) and not m.hopeless(1, 2) and m.hopeless(0, 3)
    assert not m.ended(2) and m.ended(3)
    x, P = m.birth([1, 2, 3], 0.01 * np.eye(3))
    np.testing.assert_array_equal(x, [1, 2, 3, 0, 0, 0])
    np.testing.assert_allclose(np.diag(P), [0.01] * 3 + [0.25] * 3)
    with pytest.raises(ValueError, match="confirm_window"):
        MOfN(confirm_hits=4, confirm_window=3)


def test_a_custom_management_part_replaces_the_default():
    """1-of-1 confirmation (every detection a track) through the ``management`` argument: a
    lone detection becomes a track, which the default 3-of-4 drops."""
    t = np.arange(5) * 0.25
    one = track_detections(np.array([2]), t, [[0, 0, 18.0]], _iso(1, 0.01),
                           management=MOfN(confirm_hits=1, confirm_window=1))
    assert len(one) == 1 and one[0].pings == [2]
    assert track_detections(np.array([2]), t, [[0, 0, 18.0]], _iso(1, 0.01)) == []


def test_resolution_covariance_is_a_uniform_cell():
    """On boresight (θ = φ = 0) the cell's spreads are δ_r/√12 along z (range), r δ_θ/√12
    along x (azimuth) and r δ_φ/√12 along y (elevation), uncorrelated."""
    C = resolution_covariance([20.0], [0.0], [0.0], range_resolution_m=0.04,
                              azimuth_resolution_rad=0.027, elevation_resolution_rad=0.015)[0]
    np.testing.assert_allclose(np.sqrt(np.diag(C)), np.array([20 * 0.027, 20 * 0.015, 0.04]) / np.sqrt(12),
                               rtol=1e-12)
    np.testing.assert_allclose(C - np.diag(np.diag(C)), 0.0, atol=1e-15)


def test_resolution_gate_keeps_a_split_echo_from_starting_a_second_track():
    """One fish at 0.35 m/s whose echo shows a second peak 2 cm beside the first in range and
    ¼ azimuth cell across (a fluctuating swimbladder, an echo merged with a neighbour's) on 3
    of every 4 pings from ping 8: without the resolution gate the second peak confirms a track
    of its own (3 of 4); with it the peak lies in the fish's cell and starts nothing — one
    track, holding every ping."""
    n, dt = 30, 0.25
    t = np.arange(n) * dt
    fish = np.c_[np.zeros(n), np.zeros(n), 20 - 0.35 * t]
    pings, pos = list(range(n)), list(fish)
    for k in range(8, n):
        if k % 4:
            pings.append(k)
            pos.append(fish[k] + [0.125 * 0.5 / 2, 0, 0.02])
    pings, pos = np.array(pings), np.array(pos)
    R = _iso(len(pings), 0.005)
    cell = resolution_covariance(np.full(len(pings), 20.0), np.zeros(len(pings)), np.zeros(len(pings)),
                                 range_resolution_m=0.04, azimuth_resolution_rad=0.5 / 20,
                                 elevation_resolution_rad=0.015)
    off = track_detections(pings, t, pos, R, accel_sd_m_s2=0.05)
    on = track_detections(pings, t, pos, R, resolution_m2=cell, resolution_cells=1.0, accel_sd_m_s2=0.05)
    assert len(off) == 2
    assert len(on) == 1 and len(on[0].pings) == n
    assert all(j >= 0 for j in on[0].detection)


def test_confirm_resolved_keeps_a_split_echo_born_at_the_first_ping_from_a_second_track():
    """The same split echo from the first ping on, before any track is confirmed: without
    ``confirm_resolved`` both peaks are born together and both tracks confirm (the resolution
    gate blocks births only near confirmed tracks); with it the junior track's hits all lie in
    the senior's cell, so it never confirms — one track. A second fish that swims off sideways
    from ping 12 (resolved from then on) still gets its own track."""
    n, dt = 30, 0.25
    t = np.arange(n) * dt
    fish = np.c_[np.zeros(n), np.zeros(n), 20 - 0.35 * t]
    peak = fish + [0.125 * 0.5 / 2, 0, 0.02]
    pings, pos = list(range(n)) + list(range(n)), list(fish) + list(peak)
    pings, pos = np.array(pings), np.array(pos)
    R = _iso(len(pings), 0.005)
    cell = resolution_covariance(np.full(len(pings), 20.0), np.zeros(len(pings)), np.zeros(len(pings)),
                                 range_resolution_m=0.04, azimuth_resolution_rad=0.5 / 20,
                                 elevation_resolution_rad=0.015)
    kw = dict(resolution_m2=cell, resolution_cells=1.0, accel_sd_m_s2=0.05)
    assert len(track_detections(pings, t, pos, R, confirm_resolved=False, **kw)) == 2
    on = track_detections(pings, t, pos, R, confirm_resolved=True, **kw)
    assert len(on) == 1 and len(on[0].pings) == n
    # a real second fish: side by side (within the cell) for 3 s, then off sideways at 0.3 m/s
    other = peak.copy()
    other[12:, 0] += 0.3 * (t[12:] - t[12])
    pos2 = np.concatenate([fish, other])
    assert len(track_detections(pings, t, pos2, R, confirm_resolved=True, **kw)) == 2


def test_tracking_parts_are_chosen_in_the_settings_and_refused_with_one_line():
    from processing.base.config import ConfigError
    from processing.settings import ProcessingSettings, TrackSettings
    assert TrackSettings(association="jpda", method="alpha_beta", resolution_cells=0).association == "jpda"
    assert TrackSettings(split="none").split == "none"
    for bad, word in (({"association": "nn"}, "association"), ({"resolution_cells": -1}, "resolution_cells"),
                      ({"method": "ukf"}, "method"), ({"split": "yes"}, "split"),
                      ({"split_probability": 1.0}, "split_probability")):
        with pytest.raises((ConfigError, ValueError)) as e:
            ProcessingSettings.model_validate({"track": bad})
        assert word in str(e.value) and "Traceback" not in str(e.value)


# the fan-crossing split (processing/tracking/splitting.py): a fan 0.28 m thick (0.84° at 19 m),
# fish crossing it at 0.08 m/s, detections 0.25 s apart placed through the fan with σ 4 cm (the
# interferometer's at 20 dB signal-to-interference, as measurement_covariance gives them)
_W, _SIG, _DT = 0.28, 0.04, 0.25


def _one_behind_the_other(rng, lag_s=2.5, speed=0.08, n=48):
    """Two fish crossing the fan one behind the other, ``lag_s`` apart, at one range and
    azimuth: each ping gives one echo, the fish nearer the fan's centre plane (the stronger
    echo; the other merges into it). Returns times (s), the echo's u (m) and which fish (0, 1)."""
    t = np.arange(n) * _DT
    u_a = -0.5 + speed * t
    u_b = u_a - speed * lag_s
    fish = (np.abs(u_b) < np.abs(u_a)).astype(int)
    u = np.where(fish == 1, u_b, u_a) + rng.normal(0, _SIG, n)
    return t, u, fish


def test_fan_crossing_split_cuts_where_the_second_fish_takes_the_echo():
    """Two fish crossing the fan one behind the other (2.5 s apart: 0.2 m through the fan, 5 σ)
    give one echo sequence that steps back through the fan where the second fish's echo takes
    over; the cut falls there (within one ping), on every noise draw."""
    from processing.tracking.splitting import FanCrossingSplit
    split = FanCrossingSplit(0.999, 3)
    for seed in range(20):
        t, u, fish = _one_behind_the_other(np.random.default_rng(seed))
        cuts = split.breaks(t, u, np.full(t.size, _SIG**2), np.full(t.size, _W))
        assert len(cuts) == 1
        assert abs(cuts[0] - np.argmax(fish)) <= 1


def test_fan_crossing_split_leaves_one_fish_whole_at_its_false_alarm_bound():
    """One fish crossing the fan (a straight line through it plus noise): a cut is a false
    alarm. The best of k−5 breaks is tested, each at the probability p, so the false-alarm rate
    is at most (k−5)(1−p) (Bonferroni); measured over 400 draws it stays below that bound (and
    the test's other conditions — both parts moving the same way, a step back, a dwell longer
    than one fish's — make it far rarer). A fish swimming along the fan (drifting through it at
    0.02 m/s, a strong clean echo: σ 1.3 cm, the interferometer's at 30 dB) whose track hops
    back 0.1 m onto a neighbour across the centre plane is not cut either, though every other
    condition holds (without the dwell condition it is cut on every draw): the whole record
    (12 s) is shorter than one fish that slow takes to cross the fan (14 s), so its dwell there
    is no evidence of a second fish."""
    from processing.tracking.splitting import FanCrossingSplit
    split = FanCrossingSplit(0.999, 3)
    rng = np.random.default_rng(1)
    n, draws = 48, 400
    t = np.arange(n) * _DT
    var, width = np.full(n, _SIG**2), np.full(n, _W)
    false = sum(bool(split.breaks(t, -0.5 + 0.08 * t + rng.normal(0, _SIG, n), var, width)) for _ in range(draws))
    assert false / draws <= (n - 5) * (1 - split.probability)
    along = -0.1 + 0.02 * t - 0.1 * (t > 6.0)
    clean = 0.013
    for _ in range(20):
        assert split.breaks(t, along + rng.normal(0, clean, n), np.full(n, clean**2), width) == []


def test_tracker_with_the_fan_crossing_split_gives_each_fish_its_track():
    """Through the tracker: the two fish of one echo sequence (also swimming along the fan at
    0.1 m/s, so range and azimuth say nothing) make one track without the split — the second
    fish's echo stays in the first track's gate — and two with it, each holding one fish's
    detections but for the ping at the hand-over."""
    from processing.tracking.splitting import FanCrossingSplit, splitter
    rng = np.random.default_rng(3)
    t, u, fish = _one_behind_the_other(rng)
    n = t.size
    pos = np.c_[0.1 * t + rng.normal(0, 0.01, n), u, 19.0 + rng.normal(0, 0.01, n)]
    R = np.repeat(np.diag([0.01**2, _SIG**2, 0.01**2])[None], n, axis=0)
    normal = np.tile([0.0, 1.0, 0.0], (n, 1))
    kw = dict(accel_sd_m_s2=0.05, max_misses=10, through_fan=normal, fan_width_m=np.full(n, _W))
    whole = track_detections(np.arange(n), t, pos, R, split=splitter("none"), **kw)
    assert len(whole) == 1
    cut = track_detections(np.arange(n), t, pos, R, split=FanCrossingSplit(0.999, 3), **kw)
    assert len(cut) == 2
    held = [fish[[j for j in tr.detection if j >= 0]] for tr in cut]
    assert np.sum(held[0] != 0) <= 1 and np.sum(held[1] != 1) <= 1
    # the second part is filtered again from its own first detection, so its states follow it
    assert cut[1].pings[0] >= np.argmax(fish) - 1
    assert len(cut[1].smoothed) == len(cut[1].pings)


def test_a_one_hit_confirmation_still_tracks_with_the_default_split():
    """``track.confirm_hits: 1`` is an accepted setting, and processing/tracking/tracks.py hands
    it to the default split as the hits each part must hold; a part is a line through the fan,
    which takes two detections, so the split asks for two — it must not refuse the setting
    (it raised "split min_hits must be at least 2" from inside the tracker) — and still finds
    the second fish."""
    from processing.settings import TrackSettings
    from processing.tracking.splitting import splitter
    st = TrackSettings(confirm_hits=1, confirm_window=1)
    split = splitter(st.split, probability=st.split_probability, min_hits=st.confirm_hits)
    assert split.min_hits >= 2
    t, u, fish = _one_behind_the_other(np.random.default_rng(0))
    cuts = split.breaks(t, u, np.full(t.size, _SIG**2), np.full(t.size, _W))
    assert len(cuts) == 1 and abs(cuts[0] - np.argmax(fish)) <= 1
