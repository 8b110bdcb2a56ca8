"""HOTA, nMAE and MOTChallenge files (processing/tracking/hota.py): hand-derived values on
hand-built fixtures, agreement with the reference implementation TrackEval (the ``trackeval``
package, a test dependency) to 1e-9 given the same similarity matrices, the scores in
/Processing/Tracks and ``abacus track --json``, and ``abacus track --mot`` read back."""
from __future__ import annotations

import json

import numpy as np
import pytest

from processing.tracking.hota import (ALPHAS, hota, hota_combined, localisation_similarity, nmae,
                                      read_mot, write_mot)

D_MAX = 0.3          # m: the tracker's default score_distance_m
FIELDS = ("hota", "deta", "assa", "loca", "detre", "detpr", "assre", "asspr", "tp", "fn", "fp")
TRACKEVAL = {"hota": "HOTA", "deta": "DetA", "assa": "AssA", "loca": "LocA", "detre": "DetRe",
             "detpr": "DetPr", "assre": "AssRe", "asspr": "AssPr", "tp": "HOTA_TP", "fn": "HOTA_FN",
             "fp": "HOTA_FP"}


# ------------------------------------------------------------------ fixtures: 3-D positions per frame

def _fish(n_fish, n_frames, spacing=2.0):
    """n_fish fish on straight, parallel 3-D paths 2 m apart (far beyond D_MAX), shape
    (n_frames, n_fish, 3)."""
    t = np.arange(n_frames)[:, None]
    f = np.arange(n_fish)[None, :]
    return np.stack([0.1 * t + 0 * f, spacing * f + 0 * t, 18.0 + 0.01 * t + 0 * f], -1)


def _frames(truth, tracks, d_max=D_MAX):
    """(gt_ids, tracker_ids, similarity) per frame from ``truth`` and ``tracks``: dicts
    frame → {id: position (3,)}."""
    n = max(max(truth, default=-1), max(tracks, default=-1)) + 1
    gi, ti, sims = [], [], []
    for k in range(n):
        g = truth.get(k, {})
        h = tracks.get(k, {})
        gi.append(np.array(sorted(g), int))
        ti.append(np.array(sorted(h), int))
        sims.append(localisation_similarity(np.array([g[i] for i in sorted(g)]).reshape(-1, 3),
                                            np.array([h[i] for i in sorted(h)]).reshape(-1, 3), d_max))
    return gi, ti, sims


def _as_frames(paths, frames=None, ids=None, offset=None):
    """{frame: {id: position}} from paths (n_frames, n, 3), keeping ``frames[j]`` of path j
    under ``ids[j]`` (default: all frames, id j), shifted by ``offset`` (3,) m."""
    out: dict = {}
    n = paths.shape[1]
    for j in range(n):
        for k in (range(paths.shape[0]) if frames is None or frames[j] is None else frames[j]):
            who = j if ids is None else ids[j](k) if callable(ids[j]) else ids[j]
            out.setdefault(k, {})[who] = paths[k, j] + (0 if offset is None else np.asarray(offset))
    return out


def _trackeval(gt_ids, tracker_ids, sims):
    """TrackEval's HOTA (``trackeval.metrics.HOTA.eval_sequence``) of the same frames, its
    identities relabelled 0..k−1 as its datasets do before calling it."""
    from trackeval.metrics import HOTA
    g_all = np.unique(np.concatenate(gt_ids)) if gt_ids else np.zeros(0, int)
    t_all = np.unique(np.concatenate(tracker_ids)) if tracker_ids else np.zeros(0, int)
    data = {"num_gt_dets": int(sum(len(g) for g in gt_ids)),
            "num_tracker_dets": int(sum(len(t) for t in tracker_ids)),
            "num_gt_ids": int(g_all.size), "num_tracker_ids": int(t_all.size),
            "gt_ids": [np.searchsorted(g_all, g).astype(int) for g in gt_ids],
            "tracker_ids": [np.searchsorted(t_all, t).astype(int) for t in tracker_ids],
            "similarity_scores": [np.asarray(s, float) for s in sims]}
    return HOTA().eval_sequence(data)


def _agree(mine, ref, tol=1e-9):
    for f in FIELDS:
        np.testing.assert_allclose(getattr(mine, f), np.asarray(ref[TRACKEVAL[f]], float), rtol=0, atol=tol,
                                   err_msg=f)
    for name, key in (("HOTA", "HOTA"), ("DetA", "DetA"), ("AssA", "AssA"), ("LocA", "LocA")):
        assert abs(getattr(mine, name) - float(np.mean(ref[key]))) <= tol, name


def _fixture(name):
    """The hand-built fixtures: (truth, tracks) as {frame: {id: position}}."""
    fish2, fish3 = _fish(2, 10), _fish(3, 10)
    if name == "identity":                       # every fish followed exactly by its own track
        return _as_frames(fish3), _as_frames(fish3, ids=[10, 11, 12])
    if name == "id_switch":                      # two tracks swap their fish half-way
        return _as_frames(fish2), _as_frames(fish2, ids=[lambda k: 10 if k < 5 else 11,
                                                         lambda k: 11 if k < 5 else 10])
    if name == "fragmentation":                  # one fish, two tracks with a 2-frame gap between
        one = _fish(1, 10)
        a = _as_frames(one, frames=[range(0, 4)], ids=[10])
        b = _as_frames(one, frames=[range(6, 10)], ids=[11])
        return _as_frames(one), {k: {**a.get(k, {}), **b.get(k, {})} for k in range(10)}
    if name == "half_switch":                    # one fish, one track for its first half, another for the second
        one = _fish(1, 10)
        return _as_frames(one), _as_frames(one, ids=[lambda k: 10 if k < 5 else 11])
    if name == "false_track":                    # two fish tracked exactly, one track 5 frames long where no fish is
        tr = _as_frames(fish2, ids=[10, 11])
        for k in range(3, 8):
            tr[k][12] = np.array([0.0, 10.0, 18.0])
        return _as_frames(fish2), tr
    if name == "missed_track":                   # three fish, the third never tracked
        return _as_frames(fish3), _as_frames(fish2, ids=[10, 11])
    if name == "offset":                         # every track 0.26 d_max from its fish: S = 0.74
        return _as_frames(fish2), _as_frames(fish2, ids=[10, 11], offset=[0.26 * D_MAX, 0, 0])
    raise KeyError(name)


HAND = {
    # HOTA, DetA, AssA, LocA derived by hand from the definitions (module docstring)
    "identity": (1.0, 1.0, 1.0, 1.0),
    # each match: TPA 5 of a fish of 10 points and a track of 10 → A = 5 / (10 + 10 − 5) = 1/3
    "id_switch": (np.sqrt(1 / 3), 1.0, 1 / 3, 1.0),
    # TP 8, FN 2 → DetA 0.8; each match: TPA 4, fish 10, track 4 → A = 4 / 10 = 0.4
    "fragmentation": (np.sqrt(0.8 * 0.4), 0.8, 0.4, 1.0),
    # each match: TPA 5, fish 10, track 5 → A = 0.5
    "half_switch": (np.sqrt(0.5), 1.0, 0.5, 1.0),
    # TP 20, FP 5 → DetA 0.8; associations perfect
    "false_track": (np.sqrt(0.8), 0.8, 1.0, 1.0),
    # TP 20, FN 10 → DetA 2/3
    "missed_track": (np.sqrt(2 / 3), 2 / 3, 1.0, 1.0),
    # S = 0.74 matches at α = 0.05…0.70 (14 of 19): HOTA_α = DetA_α = 1 there, 0 above; LocA_α
    # = 0.74 there and 1 (TrackEval's value without a match) above
    "offset": (14 / 19, 14 / 19, 14 / 19, (14 * 0.74 + 5) / 19),
}


@pytest.mark.parametrize("name", sorted(HAND))
def test_hota_of_hand_built_fixtures_is_the_hand_derived_value_and_trackevals(name):
    frames = _frames(*_fixture(name))
    mine = hota(*frames)
    h, d, a, l_ = HAND[name]
    assert mine.HOTA == pytest.approx(h, abs=1e-12)
    assert mine.DetA == pytest.approx(d, abs=1e-12)
    assert mine.AssA == pytest.approx(a, abs=1e-12)
    assert mine.LocA == pytest.approx(l_, abs=1e-12)
    _agree(mine, _trackeval(*frames))


def _random_run(seed, n_fish=6, n_frames=30):
    """Fish on noisy, crossing paths within a few D_MAX of each other; tracks that follow them
    with position noise, drop points, swap identities at random frames, and a few false points:
    a case where the matching's choices matter."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(-0.6, 0.6, (n_fish, 3))
    vel = rng.normal(0, 0.05, (n_fish, 3))
    truth, tracks = {}, {}
    owner = np.arange(n_fish) + 100
    for k in range(n_frames):
        pos = start + k * vel + rng.normal(0, 0.01, (n_fish, 3))
        present = rng.random(n_fish) > 0.1
        truth[k] = {int(i): pos[i] for i in np.flatnonzero(present)}
        if rng.random() < 0.15:                           # an ID switch between two tracks
            i, j = rng.choice(n_fish, 2, replace=False)
            owner[[i, j]] = owner[[j, i]]
        if rng.random() < 0.05:                           # a fragmentation: a new track id
            owner[rng.integers(n_fish)] = 1000 + k
        seen = present & (rng.random(n_fish) > 0.15)
        tracks[k] = {int(owner[i]): pos[i] + rng.normal(0, 0.08, 3) for i in np.flatnonzero(seen)}
        for m in range(rng.poisson(0.5)):                 # false points
            tracks[k][5000 + m] = rng.uniform(-0.8, 0.8, 3)
    return truth, tracks


@pytest.mark.parametrize("seed", range(6))
def test_hota_agrees_with_trackeval_on_crossing_noisy_runs(seed):
    frames = _frames(*_random_run(seed))
    mine = hota(*frames)
    ref = _trackeval(*frames)
    _agree(mine, ref)
    assert 0 < mine.HOTA < 1 and 0 < mine.LocA < 1


def test_hota_over_a_set_of_runs_is_trackevals_combination():
    from trackeval.metrics import HOTA
    runs = [_frames(*_random_run(s)) for s in range(4)] + [_frames(*_fixture("false_track"))]
    mine = hota_combined([hota(*r) for r in runs])
    ref = HOTA().combine_sequences({f"run{i}": _trackeval(*r) for i, r in enumerate(runs)})
    _agree(mine, ref)


def test_empty_runs_follow_trackevals_conventions():
    truth, _ = _fixture("missed_track")
    for t, h in ((truth, {}), ({}, truth)):
        frames = _frames(t, h)
        mine = hota(*frames)
        assert mine.HOTA == 0.0 and mine.LocA == 1.0
        _agree(mine, _trackeval(*frames))


def test_thresholds_and_similarity():
    np.testing.assert_allclose(ALPHAS, np.arange(1, 20) * 0.05, atol=1e-12)
    s = localisation_similarity([[0, 0, 0]], [[0, 0, 0], [0.15, 0, 0], [0, 0.3, 0], [0, 0, 2.0]], 0.3)
    np.testing.assert_allclose(s, [[1.0, 0.5, 0.0, 0.0]], atol=1e-12)
    with pytest.raises(ValueError, match="shaped"):
        hota([np.array([1, 2])], [np.array([1])], [np.ones((1, 2))])
    with pytest.raises(ValueError, match="twice"):
        hota([np.array([1, 1])], [np.array([1])], [np.ones((2, 1))])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        hota([np.array([1])], [np.array([1])], [np.full((1, 1), 1.5)])


def test_nmae_sums_absolute_errors_over_runs():
    # 9, 12, 10 counted for 10 each: |−1| + |+2| + 0 = 3 of 30 (the signed errors, +1, would nearly cancel)
    assert nmae([9, 12, 10], [10, 10, 10]) == pytest.approx(0.1, abs=1e-15)
    assert nmae(4, 5) == pytest.approx(0.2, abs=1e-15)
    assert np.isnan(nmae([0, 0], [0, 0]))


# ------------------------------------------------------------------ in the product

def _tracks_dataset(truth, tracks_of_truth):
    """A /Processing/Tracks-shaped dataset whose points are ``tracks_of_truth`` (rows of the
    truth table to copy, per track), all inside the counting volume."""
    import xarray as xr
    pt, pp, pos = [], [], []
    for i, rows in enumerate(tracks_of_truth):
        for r in rows:
            pt.append(i)
            pp.append(int(truth["target_ping_index"][r]))
            pos.append([truth[f"target_world_{a}"][r] for a in "xyz"])
    pos = np.array(pos, float)
    n, m = len(tracks_of_truth), len(pt)
    return xr.Dataset(
        {"point_track": ("track_point", np.array(pt)), "point_ping_index": ("track_point", np.array(pp)),
         "point_detection": ("track_point", np.arange(m)), "point_in_volume": ("track_point", np.ones(m, np.int8)),
         "point_world_x": ("track_point", pos[:, 0]), "point_world_y": ("track_point", pos[:, 1]),
         "point_world_z": ("track_point", pos[:, 2]), "point_ts_comp": ("track_point", np.full(m, np.nan)),
         "track_speed": ("track", np.zeros(n)), "track_ts": ("track", np.full(n, np.nan))},
        attrs={"track_count": n})


def _truth(n_fish=3, n_pings=8):
    paths = _fish(n_fish, n_pings)
    ping, fid = np.meshgrid(np.arange(n_pings), np.arange(n_fish), indexing="ij")
    t = {"target_ping_index": ping.ravel(), "target_id": 1_000_000 + fid.ravel(),
         "target_in_counting_volume": np.ones(ping.size, np.int8),
         "target_ts": np.full(ping.size, -40.0)}
    for j, a in enumerate("xyz"):
        t[f"target_world_{a}"] = paths[..., j].ravel()
        t[f"target_velocity_world_{a}"] = np.zeros(ping.size)
    return t


def test_score_tracks_adds_hota_and_nmae_to_the_tracks_attributes():
    """A tracker that follows 3 fish exactly: HOTA = DetA = AssA = LocA = 1 and nMAE 0; the
    same with the third fish's track cut in two halves: 4 tracks counted for 3 fish (nMAE 1/3)
    and the third fish's associations 1/2, so AssA = (16 · 1 + 8 · 1/2) / 24 = 5/6."""
    from processing.tracking.scores import score_tracks
    truth = _truth()
    rows = [np.flatnonzero(truth["target_id"] == 1_000_000 + j) for j in range(3)]
    kw = dict(volume=None, to_sonar=None, row_of_ping_index={p: p for p in range(8)}, max_distance_m=D_MAX)
    a = score_tracks(_tracks_dataset(truth, rows), truth, **kw).attrs
    for k in ("hota", "deta", "assa", "loca"):
        assert a[k] == pytest.approx(1.0, abs=1e-12), k
    assert a["count_nmae"] == 0.0 and a["true_passages"] == 3
    a = score_tracks(_tracks_dataset(truth, rows[:2] + [rows[2][:4], rows[2][4:]]), truth, **kw).attrs
    assert a["assa"] == pytest.approx(5 / 6, abs=1e-12) and a["deta"] == pytest.approx(1.0, abs=1e-12)
    assert a["hota"] == pytest.approx(np.sqrt(5 / 6), abs=1e-12)
    assert a["count_nmae"] == pytest.approx(1 / 3, abs=1e-15)


def test_mot_lines_round_trip(tmp_path):
    xyz = np.array([[0.1, -0.2, 18.0], [1.23456, 2.0, 19.5], [0.0, 0.0, 17.0]])
    write_mot(tmp_path / "t.txt", [3, 1, 1], [2, 5, 1], xyz, [1, 0, 1])
    lines = (tmp_path / "t.txt").read_text().splitlines()
    assert lines == ["1,1,-1,-1,-1,-1,1,0.0000,0.0000,17.0000", "1,5,-1,-1,-1,-1,0,1.2346,2.0000,19.5000",
                     "3,2,-1,-1,-1,-1,1,0.1000,-0.2000,18.0000"]
    back = read_mot(tmp_path / "t.txt")
    assert back["frame"].tolist() == [1, 1, 3] and back["id"].tolist() == [1, 5, 2]
    assert back["bb_left"].tolist() == [-1, -1, -1] and back["conf"].tolist() == [1, 0, 1]


SCHOOL_PINGS = 12


@pytest.fixture(scope="module")
def school(tmp_path_factory):
    """scenes/school_tracks.yaml (20 fish) cut to 12 pings, simulated once."""
    from .conftest import ROOT
    from .test_cli import abacus
    work = tmp_path_factory.mktemp("school")
    text = (ROOT / "scenes" / "school_tracks.yaml").read_text()
    assert "\npings:\n  count: 48\n" in text
    (work / "school.yaml").write_text(text.replace("\npings:\n  count: 48\n", f"\npings:\n  count: {SCHOOL_PINGS}\n"))
    r = abacus("simulate", "school.yaml", "-o", "s.nc", cwd=work)
    assert r.returncode == 0, r.stderr
    return work


def test_abacus_track_json_and_mot_files_of_a_small_school(school):
    """``abacus track --json --mot DIR``: HOTA, DetA, AssA, LocA, nMAE and the passages in strict
    JSON; DIR/tracks.txt one line per track point, DIR/gt.txt one per true fish per ping, each
    reading back as the dataset holds it; HOTA recomputed by TrackEval from the files' lines
    (positions rounded to 0.1 mm) is the command's."""
    import processing
    from processing.base.contract import TRUTH_GROUP
    from processing.tracking.tracks import tracks_of

    from .test_cli import abacus
    r = abacus("track", "s.nc", "--json", "--mot", "mot", "-o", "t.nc", cwd=school)
    assert r.returncode == 0, r.stderr

    def refuse(token):
        raise AssertionError(f"not strict JSON: {token}")
    s = json.loads(r.stdout, parse_constant=refuse)["summary"]
    for k in ("hota", "deta", "assa", "loca"):
        assert 0.0 < s[k] <= 1.0, (k, s[k])
    assert s["counted_passages"] == s["track_count"] and s["true_passages"] > 0
    assert s["nmae"] == pytest.approx(abs(s["counted_passages"] - s["true_passages"]) / s["true_passages"])
    assert sorted(p.name for p in (school / "mot").iterdir()) == ["gt.txt", "tracks.txt"]

    tree = processing.open_tree(school / "t.nc")
    ds = tracks_of(tree)
    gt = tree[TRUTH_GROUP].ds
    tr_lines = (school / "mot" / "tracks.txt").read_text().splitlines()
    gt_lines = (school / "mot" / "gt.txt").read_text().splitlines()
    assert len(tr_lines) == ds.sizes["track_point"] > 0
    assert len(gt_lines) == gt["target_id"].size == 20 * SCHOOL_PINGS
    tr, g = read_mot(school / "mot" / "tracks.txt"), read_mot(school / "mot" / "gt.txt")
    order = np.lexsort((ds["point_track"].values, ds["point_ping_index"].values))
    assert tr["frame"].tolist() == (ds["point_ping_index"].values[order] + 1).tolist()
    assert tr["id"].tolist() == (ds["point_track"].values[order] + 1).tolist()
    assert tr["conf"].tolist() == ds["point_in_volume"].values[order].tolist()
    for a in "xyz":
        np.testing.assert_allclose(tr[a], ds[f"point_world_{a}"].values[order], atol=5.1e-5)
    go = np.lexsort((gt["target_id"].values, gt["target_ping_index"].values))
    assert g["id"].tolist() == (gt["target_id"].values[go] + 1).tolist()
    assert g["conf"].tolist() == gt["target_in_counting_volume"].values[go].tolist()
    np.testing.assert_allclose(g["z"], gt["target_world_z"].values[go], atol=5.1e-5)

    # score the files as another tool would: the truth lines with conf 1 (inside the counting
    # volume) per frame, the track lines preprocessed as TrackEval's MOTChallenge reader does
    # with distractors: a track line matched (Hungarian, within D_MAX) to a fish outside the
    # volume is dropped, an unmatched one outside it too; then HOTA by TrackEval
    from scipy.optimize import linear_sum_assignment
    gi, ti, sims = [], [], []
    for f in range(1, SCHOOL_PINGS + 1):
        ga, tb = np.flatnonzero(g["frame"] == f), np.flatnonzero(tr["frame"] == f)
        keep = tr["conf"][tb] == 1
        if ga.size and tb.size:
            d = np.linalg.norm(np.c_[g["x"][ga], g["y"][ga], g["z"][ga]][:, None]
                               - np.c_[tr["x"][tb], tr["y"][tb], tr["z"][tb]][None], axis=-1)
            c = np.where(d <= D_MAX, d, 1e9)
            i, j = linear_sum_assignment(c)
            ok = c[i, j] < 1e9
            keep[j[ok]] = g["conf"][ga[i[ok]]] == 1
        a = ga[g["conf"][ga] == 1]
        b = tb[keep]
        gi.append(g["id"][a])
        ti.append(tr["id"][b])
        sims.append(localisation_similarity(np.c_[g["x"][a], g["y"][a], g["z"][a]],
                                            np.c_[tr["x"][b], tr["y"][b], tr["z"][b]], D_MAX))
    ref = _trackeval(gi, ti, sims)
    # 0.1 mm of rounding moves S by ≤ 6e-4: a match on a threshold may flip, one point at one α
    assert float(np.mean(ref["HOTA"])) == pytest.approx(s["hota"], abs=0.02)
    assert float(np.mean(ref["DetA"])) == pytest.approx(s["deta"], abs=0.02)
    _agree(hota(gi, ti, sims), ref)

    # a recording has no truth: the tracks alone
    import xarray as xr

    from abacus.cli.track import write_mot_files
    bare = xr.DataTree.from_dict({n.path: n.ds for n in tree.subtree if n.path.strip("/") != TRUTH_GROUP})
    (school / "bare").mkdir()
    assert [p.name for p in write_mot_files(bare, school / "bare")] == ["tracks.txt"]
    assert (school / "bare" / "tracks.txt").read_text() == (school / "mot" / "tracks.txt").read_text()


def test_abacus_track_mot_is_all_or_nothing(school):
    """An existing --mot folder is refused without --overwrite, and nothing of a failed run is
    left beside it."""
    from .test_cli import abacus
    (school / "keep").mkdir()
    (school / "keep" / "mine.txt").write_text("x")
    r = abacus("track", "s.nc", "--mot", "keep", cwd=school)
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert [p.name for p in (school / "keep").iterdir()] == ["mine.txt"]
    r = abacus("track", "s.nc", "--mot", "keep", "--overwrite", cwd=school)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (school / "keep").iterdir()) == ["gt.txt", "tracks.txt"]
    assert not [p for p in school.iterdir() if p.name.startswith(".keep")]
