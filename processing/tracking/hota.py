"""HOTA, nMAE and MOTChallenge text files: tracks scored the way the fish-counting benchmarks score them.

**HOTA** (Higher Order Tracking Accuracy; Luiten, Ošep, Dendorfer, Torr, Geiger, Leal-Taixé &
Leibe, "HOTA: A Higher Order Metric for Evaluating Multi-object Tracking", International Journal
of Computer Vision 129, 548–578, 2021) splits tracking accuracy into detection, association and
localisation. For a localisation threshold α, true and tracked points of one frame (ping) are
matched one-to-one with similarity ``S ≥ α``; the matched pairs are the true positives TP_α, the
unmatched true points the misses FN_α, the unmatched tracked points the false positives FP_α.
For a match c between true identity g and track h, TPA(c) are the matches (any frame) between g
and h, FNA(c) the points of g not matched to h, FPA(c) the points of h not matched to g. Then::

    DetA_α  = |TP_α| / (|TP_α| + |FN_α| + |FP_α|)                          (detection accuracy)
    A(c)    = |TPA(c)| / (|TPA(c)| + |FNA(c)| + |FPA(c)|)                  (association of one match)
    AssA_α  = (1 / |TP_α|) Σ_{c ∈ TP_α} A(c)                              (association accuracy)
    HOTA_α  = √(DetA_α · AssA_α) = √(Σ_{c ∈ TP_α} A(c) / (|TP_α| + |FN_α| + |FP_α|))
    LocA_α  = (1 / |TP_α|) Σ_{c ∈ TP_α} S(c)                              (localisation accuracy)
    HOTA    = ∫₀¹ HOTA_α dα ≈ (1/19) Σ_{α = 0.05, 0.10, …, 0.95} HOTA_α    (likewise DetA, AssA, LocA)

The matching in each frame maximises, as the paper asks, first the number of matches, then their
association and localisation: the Hungarian algorithm (``scipy.optimize.linear_sum_assignment``)
on ``Â(g, h) · S`` where Â(g, h) is the global alignment of the two identities — the soft,
similarity-weighted count of frames in which they could match, over |g| + |h| minus it. It is
computed once per frame and thresholded at each α, exactly as the reference implementation
TrackEval (``trackeval.metrics.HOTA``, J. Luiten; the package ``trackeval``) does, including its
conventions for empty runs (no tracked points, or no true ones: HOTA = DetA = AssA = 0, LocA =
1) and for an α with no match (LocA_α = 1). ``tests/test_hota.py`` checks the two agree to 1e-9.

**Similarity in 3-D.** MOTChallenge scores image boxes with their IoU; sonar tracks are 3-D
points, so the similarity between a tracked point and a true fish is
``S = max(0, 1 − d / d_max)`` (:func:`localisation_similarity`) with d the 3-D distance (m)
and d_max the tracker's scoring distance ``track.score_distance_m`` (the same gate MOTA/IDF1
use). S plays the part of IoU: 1 for a perfect position, falling to 0 at and beyond d_max (boxes
that no longer overlap). The threshold α on S is the threshold on IoU: a match at level α is a
point within (1 − α) d_max of the fish, so α = 0.5 (MOTChallenge's customary IoU 0.5) is half the
scoring distance, and the lowest level, α = 0.05, accepts 0.95 d_max. LocA is then
1 − (mean distance of the matches) / d_max.

**nMAE** (Kay, Kulits, Stathatos, Deng, Young, Beery, Van Horn & Perona, "The Caltech Fish
Counting Dataset: A Benchmark for Multiple-Object Tracking and Counting", ECCV 2022) is the
normalised mean absolute error of counts over a set of runs (clips), ``Σ_i |ĉ_i − c_i| / Σ_i c_i``
(:func:`nmae`): the errors of single runs cannot cancel. For one run it is |ĉ − c| / c.

**MOTChallenge text files** (:func:`write_mot`, :func:`read_mot`): one line per point per frame,
``frame,id,-1,-1,-1,-1,conf,x,y,z`` — the MOTChallenge 3-D layout (MOT15's 3D-MOT: the image box
columns unset, the world position in x, y, z). abacus writes frame = ping index + 1
(MOTChallenge numbers frames from 1), id = track number + 1 or the fish's ``target_id`` + 1
(positive, as MOTChallenge's tools expect), x, y, z the world position (m) and in ``conf`` 1 where
the point lies inside the counting volume — the points abacus scores — and 0 outside (in a
MOTChallenge ground truth, a 0 there marks a line the evaluation ignores). docs/validation.md,
"MOTChallenge files", shows the layout.

Pure numpy and scipy: no tracking-metrics package is needed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ALPHAS", "Hota", "hota", "hota_combined", "localisation_similarity", "nmae",
           "MOT_FIELDS", "mot_text", "write_mot", "read_mot"]

#: the 19 localisation thresholds α = 0.05, 0.10, …, 0.95, computed as TrackEval computes them
#: (``np.arange(0.05, 0.99, 0.05)``) so that a similarity on a threshold falls on the same side
ALPHAS = np.arange(0.05, 0.99, 0.05)

_EPS = np.finfo(float).eps


@dataclass(frozen=True)
class Hota:
    """HOTA and its parts, per localisation threshold α.

    Every array has shape (19,), one value per α of :data:`ALPHAS`; the scalars are their means
    over α (the integral of the paper). Scores are dimensionless, in [0, 1].

    Attributes
    ----------
    alpha : ndarray (19,)
    hota, deta, assa, loca : ndarray (19,)
        HOTA_α, DetA_α, AssA_α, LocA_α.
    detre, detpr, assre, asspr : ndarray (19,)
        Detection recall |TP|/(|TP|+|FN|) and precision |TP|/(|TP|+|FP|); association recall
        and precision (the means over TP of |TPA|/(|TPA|+|FNA|) and |TPA|/(|TPA|+|FPA|)).
    tp, fn, fp : ndarray (19,)
        |TP_α|, |FN_α|, |FP_α| (counts of points, as floats).
    """

    alpha: np.ndarray
    hota: np.ndarray
    deta: np.ndarray
    assa: np.ndarray
    loca: np.ndarray
    detre: np.ndarray
    detpr: np.ndarray
    assre: np.ndarray
    asspr: np.ndarray
    tp: np.ndarray
    fn: np.ndarray
    fp: np.ndarray

    @property
    def HOTA(self) -> float:
        """HOTA: the mean of HOTA_α over the 19 thresholds."""
        return float(np.mean(self.hota))

    @property
    def DetA(self) -> float:
        """DetA: the mean of DetA_α over the 19 thresholds."""
        return float(np.mean(self.deta))

    @property
    def AssA(self) -> float:
        """AssA: the mean of AssA_α over the 19 thresholds."""
        return float(np.mean(self.assa))

    @property
    def LocA(self) -> float:
        """LocA: the mean of LocA_α over the 19 thresholds."""
        return float(np.mean(self.loca))

    def summary(self) -> dict:
        """``{"hota", "deta", "assa", "loca"}``: the four means over α, as floats."""
        return {"hota": self.HOTA, "deta": self.DetA, "assa": self.AssA, "loca": self.LocA}


def localisation_similarity(truth_m, tracks_m, max_distance_m: float) -> np.ndarray:
    """The similarity of true and tracked 3-D positions, ``S = max(0, 1 − d / d_max)``.

    Parameters
    ----------
    truth_m : array_like, shape (n, 3)
        True positions (m).
    tracks_m : array_like, shape (m, 3)
        Tracked positions (m), in the same frame.
    max_distance_m : float
        d_max (m), > 0: the distance at which the similarity reaches 0.

    Returns
    -------
    ndarray, shape (n, m)
        S in [0, 1]: 1 where a tracked point sits on the fish, 0 at or beyond d_max.
    """
    if not max_distance_m > 0:
        raise ValueError(f"max_distance_m must be > 0, not {max_distance_m}")
    a = np.asarray(truth_m, float).reshape(-1, 3)
    b = np.asarray(tracks_m, float).reshape(-1, 3)
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)
    return np.clip(1.0 - d / float(max_distance_m), 0.0, 1.0)


def _relabel(frames):
    """Identities of every frame as 0..k−1 (sorted), and k."""
    frames = [np.asarray(f, np.int64).reshape(-1) for f in frames]
    for t, f in enumerate(frames):
        if np.unique(f).size != f.size:
            raise ValueError(f"frame {t}: an identity appears twice ({f.tolist()})")
    allid = np.unique(np.concatenate(frames)) if frames else np.zeros(0, np.int64)
    return [np.searchsorted(allid, f) for f in frames], int(allid.size)


def _final(tp, fn, fp, assa, assre, asspr, loca) -> Hota:
    """DetA, DetRe, DetPr and HOTA from the counts and the association sums (TrackEval's
    ``_compute_final_fields``)."""
    detre = tp / np.maximum(1, tp + fn)
    detpr = tp / np.maximum(1, tp + fp)
    deta = tp / np.maximum(1, tp + fn + fp)
    return Hota(alpha=ALPHAS.copy(), hota=np.sqrt(deta * assa), deta=deta, assa=assa, loca=loca,
                detre=detre, detpr=detpr, assre=assre, asspr=asspr, tp=tp, fn=fn, fp=fp)


def hota(gt_ids, tracker_ids, similarity) -> Hota:
    """HOTA, DetA, AssA and LocA of one run (a sequence of frames).

    Parameters
    ----------
    gt_ids : sequence of array_like of int, one per frame, each shape (n_t,)
        The true identities present in each frame (any integers, each at most once a frame).
    tracker_ids : sequence of array_like of int, one per frame, each shape (m_t,)
        The track identities present in each frame.
    similarity : sequence of array_like, one per frame, each shape (n_t, m_t)
        S between each true and each tracked point of the frame, in [0, 1]
        (:func:`localisation_similarity` for 3-D positions).

    Returns
    -------
    Hota
        Per-α arrays and their means (module docstring for the equations).

    Raises
    ------
    ValueError
        Frames of different numbers, a similarity of the wrong shape or outside [0, 1], or an
        identity twice in one frame.
    """
    if not (len(gt_ids) == len(tracker_ids) == len(similarity)):
        raise ValueError(f"{len(gt_ids)} frames of true identities, {len(tracker_ids)} of tracks, "
                         f"{len(similarity)} similarity matrices: one of each per frame")
    gt, n_gt = _relabel(gt_ids)
    tr, n_tr = _relabel(tracker_ids)
    sims = []
    for t, (g, h, s) in enumerate(zip(gt, tr, similarity)):
        s = np.asarray(s, float)
        if s.size == 0 and g.size * h.size == 0:
            s = s.reshape(g.size, h.size)
        if s.shape != (g.size, h.size):
            raise ValueError(f"frame {t}: the similarity is shaped {s.shape}, not ({g.size}, {h.size})")
        if s.size and not (np.all(np.isfinite(s)) and s.min() >= 0.0 and s.max() <= 1.0):
            raise ValueError(f"frame {t}: similarities must lie in [0, 1]")
        sims.append(s)
    k = ALPHAS.size
    n_gt_dets = sum(g.size for g in gt)
    n_tr_dets = sum(h.size for h in tr)
    zeros = np.zeros(k)
    if n_tr_dets == 0 or n_gt_dets == 0:
        # TrackEval's convention: nothing to match; LocA is 1 by definition
        return _final(zeros.copy(), np.full(k, float(n_gt_dets)) if n_tr_dets == 0 else zeros.copy(),
                      np.full(k, float(n_tr_dets)) if n_tr_dets else zeros.copy(),
                      zeros.copy(), zeros.copy(), zeros.copy(), np.ones(k))

    # global alignment Â(g, h): the similarity-weighted count of frames where g and h could match
    potential = np.zeros((n_gt, n_tr))
    gt_count = np.zeros((n_gt, 1))
    tr_count = np.zeros((1, n_tr))
    for g, h, s in zip(gt, tr, sims):
        denom = s.sum(0)[np.newaxis, :] + s.sum(1)[:, np.newaxis] - s
        soft = np.zeros_like(s)
        ok = denom > 0 + _EPS
        soft[ok] = s[ok] / denom[ok]
        potential[g[:, np.newaxis], h[np.newaxis, :]] += soft
        gt_count[g] += 1
        tr_count[0, h] += 1
    alignment = potential / (gt_count + tr_count - potential)

    from scipy.optimize import linear_sum_assignment
    tp, fn, fp, loc = zeros.copy(), zeros.copy(), zeros.copy(), zeros.copy()
    matches = np.zeros((k, n_gt, n_tr))
    for g, h, s in zip(gt, tr, sims):
        if g.size == 0 or h.size == 0:
            fp += h.size
            fn += g.size
            continue
        rows, cols = linear_sum_assignment(-(alignment[g[:, np.newaxis], h[np.newaxis, :]] * s))
        for a, alpha in enumerate(ALPHAS):
            hit = s[rows, cols] >= alpha - _EPS
            r, c = rows[hit], cols[hit]
            tp[a] += r.size
            fn[a] += g.size - r.size
            fp[a] += h.size - r.size
            if r.size:
                loc[a] += sum(s[r, c])
                matches[a, g[r], h[c]] += 1
    assa, assre, asspr = zeros.copy(), zeros.copy(), zeros.copy()
    for a in range(k):
        m = matches[a]
        assa[a] = np.sum(m * (m / np.maximum(1, gt_count + tr_count - m))) / np.maximum(1, tp[a])
        assre[a] = np.sum(m * (m / np.maximum(1, gt_count))) / np.maximum(1, tp[a])
        asspr[a] = np.sum(m * (m / np.maximum(1, tr_count))) / np.maximum(1, tp[a])
    loca = np.maximum(1e-10, loc) / np.maximum(1e-10, tp)
    return _final(tp, fn, fp, assa, assre, asspr, loca)


def hota_combined(results) -> Hota:
    """HOTA over a set of runs, as TrackEval combines sequences.

    The counts |TP_α|, |FN_α|, |FP_α| add up; AssA_α (and its recall and precision) and LocA_α
    are the means of the runs' values weighted by their |TP_α|. (It is not the mean of the
    runs' HOTA.)

    Parameters
    ----------
    results : sequence of Hota
        One per run.

    Returns
    -------
    Hota
    """
    results = list(results)
    if not results:
        raise ValueError("no runs to combine")
    tp = sum(r.tp for r in results)
    fn = sum(r.fn for r in results)
    fp = sum(r.fp for r in results)
    w = lambda name: sum(getattr(r, name) * r.tp for r in results) / np.maximum(1.0, tp)  # noqa: E731
    loca = np.maximum(1e-10, sum(r.loca * r.tp for r in results)) / np.maximum(1e-10, tp)
    return _final(tp, fn, fp, w("assa"), w("assre"), w("asspr"), loca)


def nmae(counted, true) -> float:
    """The normalised mean absolute error of counts, ``Σ |ĉ_i − c_i| / Σ c_i`` (Kay et al. 2022).

    Parameters
    ----------
    counted : int or array_like of int, shape (n_runs,)
        The counts ĉ_i (e.g. tracks through the counting volume, per run).
    true : int or array_like of int, shape (n_runs,)
        The true counts c_i (fish that passed through it).

    Returns
    -------
    float
        Dimensionless (0.1 = 10 %); for one run |ĉ − c| / c. NaN when Σ c_i = 0 (no fish: the
        error has no scale).
    """
    c = np.atleast_1d(np.asarray(counted, float))
    t = np.atleast_1d(np.asarray(true, float))
    if c.shape != t.shape:
        raise ValueError(f"{c.size} counts for {t.size} true counts")
    total = float(t.sum())
    return float(np.abs(c - t).sum() / total) if total > 0 else float("nan")


# ------------------------------------------------------------------ MOTChallenge text files

#: the columns of a MOTChallenge 3-D line
MOT_FIELDS = ("frame", "id", "bb_left", "bb_top", "bb_width", "bb_height", "conf", "x", "y", "z")


def mot_text(frame, ids, xyz_m, conf) -> str:
    """MOTChallenge 3-D lines ``frame,id,-1,-1,-1,-1,conf,x,y,z``, sorted by frame then id.

    Parameters
    ----------
    frame : array_like of int, shape (n,)
        Frame numbers (from 1).
    ids : array_like of int, shape (n,)
        Identities (positive).
    xyz_m : array_like, shape (n, 3)
        World positions (m), written to 0.1 mm.
    conf : array_like, shape (n,)
        The ``conf`` column (abacus: 1 inside the counting volume, 0 outside).

    Returns
    -------
    str
        One line per row, each ending in a newline ('' for no rows).
    """
    frame = np.asarray(frame, np.int64).reshape(-1)
    ids = np.asarray(ids, np.int64).reshape(-1)
    xyz = np.asarray(xyz_m, float).reshape(-1, 3)
    conf = np.asarray(conf, float).reshape(-1)
    if not (frame.size == ids.size == xyz.shape[0] == conf.size):
        raise ValueError("frame, ids, xyz_m and conf must have one row each per line")
    order = np.lexsort((ids, frame))
    return "".join(f"{frame[i]},{ids[i]},-1,-1,-1,-1,{conf[i]:g},{xyz[i, 0]:.4f},{xyz[i, 1]:.4f},"
                   f"{xyz[i, 2]:.4f}\n" for i in order)


def write_mot(path, frame, ids, xyz_m, conf):
    """Write MOTChallenge 3-D lines (:func:`mot_text`) to ``path`` (the caller makes it atomic:
    ``abacus track --mot`` writes into a folder staged by
    :func:`processing.base.atomic.staged_set`)."""
    from pathlib import Path
    path = Path(path)
    path.write_text(mot_text(frame, ids, xyz_m, conf))
    return path


def read_mot(path) -> dict:
    """Read a MOTChallenge text file (2-D or 3-D: the first 10 comma-separated columns).

    Returns
    -------
    dict of ndarray, each shape (n,)
        The columns of :data:`MOT_FIELDS`: ``frame`` and ``id`` as int, the rest as float.
    """
    from pathlib import Path
    rows = [ln.split(",") for ln in Path(path).read_text().splitlines() if ln.strip()]
    for i, r in enumerate(rows):
        if len(r) < len(MOT_FIELDS):
            raise ValueError(f"{path}:{i + 1}: {len(r)} columns, a MOTChallenge line has at least "
                             f"{len(MOT_FIELDS)}")
    a = np.array([[float(v) for v in r[:len(MOT_FIELDS)]] for r in rows], float).reshape(-1, len(MOT_FIELDS))
    out = {name: a[:, j] for j, name in enumerate(MOT_FIELDS)}
    out["frame"] = out["frame"].astype(np.int64)
    out["id"] = out["id"].astype(np.int64)
    return out
