"""Scoring tracks against the ground truth: multi-object-tracking metrics, count, speed and TS.

The standard CLEAR-MOT (MOTA, MOTP; Bernardin & Stiefelhagen 2008) and identity (IDF1; Ristani et
al. 2016) metrics, ID switches and fragmentations come from py-motmetrics (Heindl,
https://github.com/cheind/py-motmetrics), the reference implementation the MOTChallenge
benchmarks validated theirs against — not re-derived here. The scene is scored where the thesis
counts: the true fish inside the counting volume against the track positions, matched when within
``max_distance_m`` (world frame); the volume's faces are treated as TrackEval treats MOTChallenge's
distractors (:func:`_scored_frames`): a track point following a fish outside the volume is not a
false positive, and one a centimetre outside following a fish inside is scored.

Beside those, per track: the true fish it follows (the identity of the nearest true fish within
``max_distance_m`` at most of its detected pings), its speed error (track speed − that fish's mean
speed over the track's pings) and TS error (track TS − the fish's mean σ_bs over the pings whose
detection was compensated, both in dB); and the run's true number of fish that passed through the
counting volume (distinct identities ever inside it).

HOTA with its detection, association and localisation parts (DetA, AssA, LocA; Luiten et al.
2021) is not in motmetrics: processing/tracking/hota.py computes it (pure numpy/scipy, checked
against the reference implementation TrackEval in tests/test_hota.py) on the same points, with
the 3-D localisation similarity ``S = max(0, 1 − d / max_distance_m)``; nMAE of the run's track
count (|track count − true passages| / true passages; Kay et al. 2022) beside it.

py-motmetrics is the optional extra ``metrics``: without it, scoring raises
:class:`processing.base.extras.MissingExtra`, which names the extra.
"""
from __future__ import annotations

import numpy as np
import xarray as xr

__all__ = ["score_tracks", "MOT_METRICS"]

MOT_METRICS = ("mota", "motp", "idf1", "num_switches", "num_fragmentations", "mostly_tracked",
               "num_false_positives", "num_misses", "num_unique_objects")


def _scored_frames(ds, truth, volume_inside_truth, max_distance_m, row_of_ping_index):
    """Per ping, the true fish and track points that are scored: the evaluation region as
    TrackEval preprocesses MOTChallenge data (``MotChallenge2DBox.get_preprocessed_seq_data``:
    tracker detections matched to a distractor are removed, not counted false).

    The true fish are those inside the counting volume. Every track point is first matched
    one-to-one (Hungarian, within ``max_distance_m``) against every fish, inside or outside;
    a point matched to a fish outside the volume is a correct track of a fish the volume does
    not score (removed), an unmatched point outside the volume is not scored either, and the
    rest are. So a fish at the volume's face whose track lies a centimetre beyond it is not a
    miss, nor is the track of a fish just outside a false positive.

    Returns
    -------
    list of (ndarray, ndarray)
        Per ping (ascending), rows of ``truth`` and rows of the track points scored.
    """
    from scipy.optimize import linear_sum_assignment
    tp = truth["target_ping_index"].astype(int)
    t_xyz = np.stack([truth[f"target_world_{a}"] for a in "xyz"], -1)
    pts_ping = ds["point_ping_index"].values.astype(int)
    pts_in = ds["point_in_volume"].values.astype(bool)
    pts_xyz = np.stack([ds[f"point_world_{a}"].values for a in "xyz"], -1)
    frames = []
    for p in sorted(row_of_ping_index):
        allf = np.flatnonzero(tp == p)
        h = np.flatnonzero(pts_ping == p)
        keep = pts_in[h].copy()
        if allf.size and h.size:
            d = np.linalg.norm(t_xyz[allf][:, None, :] - pts_xyz[h][None, :, :], axis=-1)
            c = np.where(d <= max_distance_m, d, 1e9)
            r, k = linear_sum_assignment(c)
            ok = c[r, k] < 1e9
            r, k = r[ok], k[ok]
            keep[k] = volume_inside_truth[allf[r]]
        frames.append((allf[volume_inside_truth[allf]], h[keep]))
    return frames


def _mot(ds, truth, volume_inside_truth, max_distance_m, row_of_ping_index):
    import warnings

    from processing.base.extras import require
    mm = require("motmetrics", "scoring tracks against the truth (MOTA, IDF1)")
    acc = mm.MOTAccumulator(auto_id=False)
    pts_xyz = np.stack([ds[f"point_world_{a}"].values for a in "xyz"], -1)
    pts_track = ds["point_track"].values.astype(int)
    t_xyz = np.stack([truth[f"target_world_{a}"] for a in "xyz"], -1)
    for frame, (o, h) in enumerate(_scored_frames(ds, truth, volume_inside_truth, max_distance_m,
                                                  row_of_ping_index)):
        d = np.linalg.norm(t_xyz[o][:, None, :] - pts_xyz[h][None, :, :], axis=-1) if o.size and h.size \
            else np.empty((o.size, h.size))
        d = np.where(d <= max_distance_m, d, np.nan)
        acc.update(truth["target_id"][o].astype(int).tolist(), pts_track[h].tolist(), d, frameid=frame)
    mh = mm.metrics.create()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        summary = mh.compute(acc, metrics=list(MOT_METRICS), name="run")
    return {k: float(summary[k].iloc[0]) for k in MOT_METRICS}


def _hota(ds, truth, volume_inside_truth, max_distance_m, row_of_ping_index):
    """HOTA, DetA, AssA, LocA of the track points inside the counting volume against the true
    fish inside it, one frame per ping (:func:`processing.tracking.hota.hota`)."""
    from processing.tracking.hota import hota, localisation_similarity
    t_ids = truth["target_id"].astype(int)
    t_xyz = np.stack([truth[f"target_world_{a}"] for a in "xyz"], -1)
    pts_xyz = np.stack([ds[f"point_world_{a}"].values for a in "xyz"], -1)
    pts_track = ds["point_track"].values.astype(int)
    gt_ids, tr_ids, sims = [], [], []
    for o, h in _scored_frames(ds, truth, volume_inside_truth, max_distance_m, row_of_ping_index):
        gt_ids.append(t_ids[o])
        tr_ids.append(pts_track[h])
        sims.append(localisation_similarity(t_xyz[o], pts_xyz[h], max_distance_m))
    return hota(gt_ids, tr_ids, sims).summary()


def score_tracks(ds: xr.Dataset, truth: dict, *, volume, to_sonar, row_of_ping_index: dict,
                 max_distance_m: float) -> xr.Dataset:
    """Add the scores against the truth to a tracks dataset.

    Parameters
    ----------
    ds : xarray.Dataset
        /Processing/Tracks as :func:`processing.tracking.tracks.track` builds it.
    truth : dict of ndarray, each shape (m,)
        Ground-truth columns: ``target_ping_index``, ``target_id``, ``target_world_x/y/z`` (m),
        ``target_velocity_world_x/y/z`` (m/s), ``target_ts`` (dB), optionally
        ``target_in_counting_volume``.
    volume : CountingVolume
    to_sonar : callable
        (ping rows (n,), world positions (n, 3)) → sonar-frame positions (n, 3).
    row_of_ping_index : dict
        Ping index → row of the record.
    max_distance_m : float

    Returns
    -------
    xarray.Dataset
        ``ds`` with per-track ``track_true_id`` (−1: follows no fish), ``track_speed_error``
        (m/s), ``track_ts_error`` (dB), and attributes ``true_passages`` (fish that passed
        through the counting volume), ``track_count_error``, ``count_nmae`` (|track count
        error| / true passages, NaN without a passage), the MOT metrics (``mota``, ``motp``
        (m), ``idf1``, ...), HOTA and its parts (``hota``, ``deta``, ``assa``, ``loca``: means
        over the localisation thresholds α = 0.05…0.95 with the similarity
        ``max(0, 1 − d / max_distance_m)``; processing/tracking/hota.py), and the mean and
        standard deviation of the speed and TS errors over the tracks that follow a fish.
    """
    tp = truth["target_ping_index"].astype(int)
    known = np.array([p in row_of_ping_index for p in tp], bool)
    t_xyz = np.stack([truth[f"target_world_{a}"] for a in "xyz"], -1)
    if "target_in_counting_volume" in truth:
        inside = truth["target_in_counting_volume"].astype(bool) & known
    else:
        rows = np.array([row_of_ping_index.get(int(p), 0) for p in tp], int)
        inside = volume.contains(to_sonar(rows, t_xyz)) & known
    scores = _mot(ds, truth, inside, max_distance_m, row_of_ping_index)
    scores.update(_hota(ds, truth, inside, max_distance_m, row_of_ping_index))
    true_passages = int(np.unique(truth["target_id"][inside]).size)
    speed_true = np.linalg.norm(np.stack([truth[f"target_velocity_world_{a}"] for a in "xyz"], -1), axis=1)
    n_tr = ds.sizes["track"]
    true_id = np.full(n_tr, -1, np.int64)
    speed_err = np.full(n_tr, np.nan)
    ts_err = np.full(n_tr, np.nan)
    pts_track = ds["point_track"].values.astype(int)
    pts_ping = ds["point_ping_index"].values.astype(int)
    pts_det = ds["point_detection"].values.astype(int)
    pts_xyz = np.stack([ds[f"point_world_{a}"].values for a in "xyz"], -1)
    pts_ts = ds["point_ts_comp"].values
    for i in range(n_tr):
        k = np.flatnonzero((pts_track == i) & (pts_det >= 0))
        ids, pings = [], []
        for j in k:
            cand = np.flatnonzero(tp == pts_ping[j])
            if cand.size == 0:
                continue
            d = np.linalg.norm(t_xyz[cand] - pts_xyz[j], axis=1)
            b = int(np.argmin(d))
            if d[b] <= max_distance_m:
                ids.append(int(truth["target_id"][cand[b]]))
                pings.append(j)
        if not ids:
            continue
        vals, counts = np.unique(ids, return_counts=True)
        fish = int(vals[np.argmax(counts)])
        true_id[i] = fish
        mine = truth["target_id"] == fish
        span = np.isin(tp, pts_ping[k]) & mine
        speed_err[i] = float(ds["track_speed"].values[i] - speed_true[span].mean())
        with_ts = np.isfinite(pts_ts[k])
        if with_ts.any():
            on = np.isin(tp, pts_ping[k][with_ts]) & mine
            true_ts = 10 * np.log10(np.mean(10 ** (truth["target_ts"][on] / 10)))
            ts_err[i] = float(ds["track_ts"].values[i] - true_ts)
    out = ds.assign(track_true_id=("track", true_id), track_speed_error=("track", speed_err),
                    track_ts_error=("track", ts_err))
    out["track_true_id"].attrs["long_name"] = "target_id of the fish the track follows, −1: none"
    out["track_speed_error"].attrs.update(units="m/s", nan_means="the track follows no true fish")
    out["track_ts_error"].attrs.update(units="dB", nan_means="no true fish, or no compensated TS")
    follows = true_id >= 0
    attrs = dict(scores)
    from processing.tracking.hota import nmae
    attrs.update(true_passages=true_passages,
                 track_count_error=int(ds.attrs["track_count"]) - true_passages,
                 count_nmae=nmae(int(ds.attrs["track_count"]), true_passages),
                 tracks_following_a_fish=int(follows.sum()))
    for name, v in (("speed_error", speed_err), ("ts_error", ts_err)):
        v = v[np.isfinite(v)]
        attrs[f"{name}_mean"] = float(v.mean()) if v.size else np.nan
        attrs[f"{name}_sd"] = float(v.std(ddof=1)) if v.size > 1 else np.nan
    out.attrs.update(attrs)
    return out
