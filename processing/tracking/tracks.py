"""The /Processing/Tracks product: fish tracked across pings, counted once, with a TS and a speed.

:func:`track` takes a dataset with detections (or makes them), locates each in the world frame
through its ping's pose, gives it a covariance from its own uncertainty and a beam-compensated
TS, tracks them (processing/tracking/filters.py) and writes /Processing/Tracks:

* per track (dim ``track``): first and last ping, number of detections, mean smoothed velocity
  (m/s, world frame) and speed, mean TS (10 log10 of the mean σ_bs of its compensated
  detections), whether it passed through the counting volume, and — with ground truth — the true
  fish it follows (majority of its matched pings) and that fish's speed and TS;
* per track point (dim ``track_point``, flat with an index column ``point_track``, as ray-query
  results are kept): ping index, the detection row (−1 where the track coasted), the smoothed
  world position, TS uncompensated/compensated;
* attributes: the track-based count (passages through the counting volume), the track-based
  density (the fish-seconds the tracks spend inside the volume over the run's duration, divided
  by the volume: the mean number present, which per-ping counts also estimate) and, with truth,
  the multi-object-tracking scores (processing/tracking/scores.py).
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from processing.base.contract import (COUNTS_GROUP, DETECTIONS_GROUP, ELEMENT_GROUP, ENVIRONMENT_GROUP, SONAR_GROUP,
                                      TRACKS_GROUP, TRUTH_GROUP)
from processing.base.dataset import DatasetError, group_of, has_group
from processing.pipeline import pose_of

__all__ = ["TRACKS_GROUP", "track", "tracks_of", "track_summary", "format_tracks",
           "write_tracks_csv", "strict_json", "truth_in_volume"]


def _ping_times_s(tree):
    eg = tree[ELEMENT_GROUP].ds
    t = eg["ping_time"].values
    if np.issubdtype(t.dtype, np.datetime64):
        return (t - t[0]) / np.timedelta64(1, "s")
    return np.asarray(t, float) - float(t[0])


def _baseline_m(tree):
    eg = tree[ELEMENT_GROUP].ds
    sub = np.asarray(eg["element_subarray"].values).astype(str)
    xyz = np.stack([eg[f"element_{a}"].values for a in "xyz"], -1)
    if not ((sub == "A").any() and (sub == "B").any()):
        return None
    return float(np.linalg.norm(xyz[sub == "B"].mean(0) - xyz[sub == "A"].mean(0)))


def _elevation_beamwidth_rad(tree, volume):
    """The transmitter's 3 dB elevation beamwidth (rad): the fan's thickness, within which
    echoes are not resolved in elevation (twice the counting volume's half-width without it)."""
    sonar = group_of(tree, SONAR_GROUP)
    if sonar is not None and "beamwidth_transmit_minor" in sonar:
        return float(np.radians(float(sonar["beamwidth_transmit_minor"])))
    return 2.0 * float(volume.elevation_halfwidth_rad)


class _Poses:
    """The sonar's pose at each ping of a record, read once (None: sonar frame = world frame)."""

    def __init__(self, tree):
        pose = pose_of(tree)
        self.position, self.rotation = ((None, None) if pose is None
                                        else (np.asarray(a, float) for a in pose))

    def rotation_of(self, ping_rows):
        """Sonar axes in world coordinates, (n, 3, 3) or (3, 3); None without a pose."""
        if self.rotation is None or self.rotation.ndim == 2:
            return self.rotation
        return self.rotation[ping_rows]

    def to_sonar(self, ping_rows, world_m):
        """World positions (n, 3) of the given ping rows (n,) in their ping's sonar frame."""
        if self.rotation is None:
            return world_m
        if self.rotation.ndim == 3:
            return np.einsum("nji,nj->ni", self.rotation[ping_rows], world_m - self.position[ping_rows])
        return (world_m - self.position) @ self.rotation


def track(tree: xr.DataTree, settings=None) -> xr.DataTree:
    """Track the detections of a dataset across pings.

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset (simulated or recorded) with or without /Processing/Detections.
    settings : ProcessingSettings, dict or path, optional
        Its ``track`` section sets the tracker (:class:`processing.settings.TrackSettings`).

    Returns
    -------
    xarray.DataTree
        A copy with /Processing/Tracks (see the module docstring).

    Raises
    ------
    processing.base.dataset.DatasetError
        The dataset has no interferometric elevation (tracking needs 3-D positions).
    """
    from processing.pipeline import RecordChain
    from processing.records import with_detections
    from processing.tracking.filters import fan_normal, measurement_covariance, resolution_covariance, track_detections
    from processing.tracking.splitting import splitter
    chain = RecordChain(tree, settings)
    tree, st = chain.tree, chain.settings
    ts_ = st.track
    if has_group(tree, DETECTIONS_GROUP):
        detected = chain.detected()          # the detections the dataset holds, as a record
    else:
        detected = chain.detect()
        tree = with_detections(chain, detected, "none")
    if not detected.interferometric:
        raise DatasetError("tracking needs 3-D positions: this dataset's mode has no "
                           "interferometric elevation (normal or combined mode)")
    det = detected.table
    rows = det["ping"].astype(int)
    world = np.stack([det[f"world_{a}_m"] for a in "xyz"], -1).reshape(-1, 3)
    usable = ~det["elevation_clipped"] if "elevation_clipped" in det else np.ones(len(rows), bool)
    c = float(tree[ENVIRONMENT_GROUP].ds["sound_speed_indicative"].values)
    f0 = float(tree[SONAR_GROUP].ds["transmit_frequency_center"].values)
    baseline = _baseline_m(tree)
    poses = _Poses(tree)
    if baseline is None:
        raise DatasetError(f"tracking needs subarrays A and B in /{ELEMENT_GROUP}/element_subarray")
    rotation = poses.rotation_of(rows)
    fan_rad = _elevation_beamwidth_rad(tree, detected.volume)
    cov = measurement_covariance(det["range_m"], det["azimuth_rad"], det["elevation_rad"],
                                 det["snr_db"], range_resolution_m=detected.range_resolution_m,
                                 azimuth_resolution_rad=detected.azimuth_resolution_rad,
                                 wavelength_m=c / f0, baseline_m=baseline,
                                 interference_db=ts_.interference_db, rotation=rotation)
    cell = resolution_covariance(det["range_m"], det["azimuth_rad"], det["elevation_rad"],
                                 range_resolution_m=detected.range_resolution_m,
                                 azimuth_resolution_rad=detected.azimuth_resolution_rad,
                                 elevation_resolution_rad=fan_rad, rotation=rotation)
    normal = fan_normal(len(rows), rotation)
    fan_width = np.asarray(det["range_m"], float) * fan_rad
    fan_centre = (np.zeros(len(rows)) if poses.position is None else
                  np.einsum("ki,ki->k", normal, np.broadcast_to(poses.position if poses.position.ndim == 1
                                                                else poses.position[rows], normal.shape)))
    targets = chain.single_targets(detected)
    ts_u, ts_c = targets["ts_uncomp_db"], targets["ts_comp_db"]
    single = np.asarray(targets["single_target"], bool)
    if ts_.resolution_cells > 0:
        # a second peak in a stronger echo's cell is left to the resolution gate, which keeps it
        # from starting a track without losing a fish side by side with a stronger one
        from processing.backscatter.single_targets import single_targets
        single = single_targets(det["ping"], det["range_m"], det["azimuth_rad"], det["amplitude"],
                                range_resolution_m=detected.range_resolution_m,
                                azimuth_resolution_rad=detected.azimuth_resolution_rad,
                                sidelobe_db=ts_.sidelobe_db, same_cell=False)
        single &= ~(ts_c < ts_.min_ts_db)
    times = _ping_times_s(tree)
    keep = np.flatnonzero(usable & single & np.all(np.isfinite(world), axis=1))
    tracks = track_detections(rows[keep], times, world[keep], cov[keep], method=ts_.method,
                              association=ts_.association, resolution_m2=cell[keep],
                              resolution_cells=ts_.resolution_cells,
                              confirm_resolved=ts_.confirm_resolved,
                              gate_probability=ts_.gate_probability, accel_sd_m_s2=ts_.accel_sd_m_s2,
                              initial_speed_sd_m_s=ts_.initial_speed_sd_m_s, alpha=ts_.alpha,
                              beta=ts_.beta, confirm_hits=ts_.confirm_hits,
                              confirm_window=ts_.confirm_window, max_misses=ts_.max_misses,
                              through_fan=normal[keep], fan_width_m=fan_width[keep],
                              fan_centre_m=fan_centre[keep],
                              split=splitter(ts_.split, probability=ts_.split_probability,
                                             min_hits=ts_.confirm_hits))
    volume = detected.volume
    ping_index_of_row = chain.ping_index
    # flat track points
    p_track, p_row, p_det, p_pos, p_in = [], [], [], [], []
    for tr in tracks:
        n = len(tr.pings)
        sm = np.array(tr.smoothed)[:, :3]
        prow = np.array(tr.pings, int)
        inside = volume.contains(poses.to_sonar(prow, sm))
        dets = np.array([keep[j] if j >= 0 else -1 for j in tr.detection], int)
        p_track.append(np.full(n, tr.track_id))
        p_row.append(prow)
        p_det.append(dets)
        p_pos.append(sm)
        p_in.append(inside)
    cat = (lambda parts, shape, dt: np.concatenate(parts) if parts else np.zeros(shape, dt))
    p_track = cat(p_track, 0, int)
    p_row = cat(p_row, 0, int)
    p_det = cat(p_det, 0, int)
    p_pos = cat(p_pos, (0, 3), float)
    p_in = cat(p_in, 0, bool)
    has = p_det >= 0
    p_ts_u = np.where(has, ts_u[np.maximum(p_det, 0)], np.nan)
    p_ts_c = np.where(has, ts_c[np.maximum(p_det, 0)], np.nan)
    n_tr = len(tracks)
    vel = np.array([np.mean(np.array(tr.smoothed)[:, 3:], axis=0) for tr in tracks]).reshape(n_tr, 3)
    first = np.array([tr.pings[0] for tr in tracks], int)
    last = np.array([tr.pings[-1] for tr in tracks], int)
    n_det = np.array([sum(j >= 0 for j in tr.detection) for tr in tracks], int)
    mean_ts = np.full(n_tr, np.nan)
    passed = np.zeros(n_tr, bool)
    for i in range(n_tr):
        k = p_track == i
        good = p_ts_c[k][np.isfinite(p_ts_c[k])]
        if good.size:
            mean_ts[i] = 10 * np.log10(np.mean(10 ** (good / 10)))
        passed[i] = p_in[k].any()
    interval = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    duration = float(times[-1] - times[0]) + interval
    fish_seconds = float(p_in.sum()) * interval
    density = fish_seconds / duration / volume.volume_m3 if duration > 0 and volume.volume_m3 > 0 else np.nan
    ds = xr.Dataset(
        {"track_first_ping": ("track", ping_index_of_row[first] if n_tr else first),
         "track_last_ping": ("track", ping_index_of_row[last] if n_tr else last),
         "track_detections": ("track", n_det),
         "track_velocity_world_x": ("track", vel[:, 0]), "track_velocity_world_y": ("track", vel[:, 1]),
         "track_velocity_world_z": ("track", vel[:, 2]),
         "track_speed": ("track", np.linalg.norm(vel, axis=1)),
         "track_ts": ("track", mean_ts),
         "track_in_volume": ("track", passed.astype(np.int8)),
         "point_track": ("track_point", p_track),
         "point_ping_index": ("track_point", ping_index_of_row[p_row] if p_row.size else p_row),
         "point_detection": ("track_point", p_det),
         "point_world_x": ("track_point", p_pos[:, 0]), "point_world_y": ("track_point", p_pos[:, 1]),
         "point_world_z": ("track_point", p_pos[:, 2]),
         "point_in_volume": ("track_point", p_in.astype(np.int8)),
         "point_ts_uncomp": ("track_point", p_ts_u), "point_ts_comp": ("track_point", p_ts_c)},
        coords={"track": np.arange(n_tr)},
        attrs={"method": ts_.method, "track_count": int(passed.sum()),
               "track_density_per_m3": density, "counting_volume_m3": volume.volume_m3,
               "counting_range_m": np.asarray(volume.range_m, float),
               "counting_azimuth_halfwidth_rad": volume.azimuth_halfwidth_rad,
               "counting_elevation_halfwidth_rad": volume.elevation_halfwidth_rad,
               "duration_s": duration})
    units = {"track_velocity_world_x": "m/s", "track_velocity_world_y": "m/s",
             "track_velocity_world_z": "m/s", "track_speed": "m/s", "track_ts": "dB re 1 m^2",
             "point_world_x": "m", "point_world_y": "m", "point_world_z": "m",
             "point_ts_uncomp": "dB re 1 m^2", "point_ts_comp": "dB re 1 m^2"}
    for k, u in units.items():
        ds[k].attrs["units"] = u
    ds["track_ts"].attrs["nan_means"] = "no detection of the track within the compensable beam"
    ds["point_ts_comp"].attrs["nan_means"] = ("a coasted point (no detection), or the two-way "
                                              "pattern at the located angle below −20 dB")
    ds["point_ts_uncomp"].attrs["nan_means"] = "a coasted point (no detection)"
    ds["point_detection"].attrs["long_name"] = "row of /Processing/Detections, −1 where the track coasted"
    from processing.tracking.scores import score_tracks
    truth = _truth_table(tree)
    if truth is not None:
        # the fish inside the volume the tracks are counted in: the simulator's own flag bounds
        # only the image's range (it knows no count.range_m or count half-widths)
        truth["target_in_counting_volume"] = _inside(truth, volume, poses, ping_index_of_row)
        ds = score_tracks(ds, truth, volume=volume, to_sonar=poses.to_sonar,
                          row_of_ping_index={int(p): i for i, p in enumerate(ping_index_of_row)},
                          max_distance_m=ts_.score_distance_m)
    out = tree.copy()
    out[TRACKS_GROUP] = xr.DataTree(ds)
    return out


def _inside(truth, volume, poses, ping_index_of_row):
    """Per truth row: inside ``volume`` at its ping's pose (False for a ping not in the record)."""
    row_of = {int(p): i for i, p in enumerate(ping_index_of_row)}
    tp = np.asarray(truth["target_ping_index"], int)
    known = np.array([int(p) in row_of for p in tp], bool)
    rows = np.array([row_of.get(int(p), 0) for p in tp], int)
    xyz = np.stack([truth[f"target_world_{a}"] for a in "xyz"], -1).reshape(-1, 3)
    return np.asarray(volume.contains(poses.to_sonar(rows, xyz)), bool) & known


def truth_in_volume(tree: xr.DataTree):
    """Whether each true fish (row of the truth table) is inside the counting volume its tracks
    were counted in (the volume of /Processing/Tracks' attributes, at each ping's pose).

    Returns
    -------
    ndarray of bool, shape (n_truth_rows,), or None without truth
    """
    from processing.base.counting_volume import CountingVolume
    from processing.base.dataset import ping_indices
    truth = _truth_table(tree)
    if truth is None:
        return None
    a = tracks_of(tree).attrs
    volume = CountingVolume(tuple(float(x) for x in np.asarray(a["counting_range_m"]).ravel()),
                            float(a["counting_azimuth_halfwidth_rad"]), float(a["counting_elevation_halfwidth_rad"]))
    return _inside(truth, volume, _Poses(tree), np.asarray(ping_indices(tree[ELEMENT_GROUP].ds), int))


def _truth_table(tree):
    gt = group_of(tree, TRUTH_GROUP)
    if gt is None:
        return None
    if "target_id" not in gt:
        return None
    out = {k: gt[k].values for k in ("target_ping_index", "target_id", "target_world_x", "target_world_y",
                                      "target_world_z", "target_ts", "target_in_counting_volume")
           if k in gt}
    for a in "xyz":
        k = f"target_velocity_world_{a}"
        out[k] = gt[k].values if k in gt else np.zeros(len(out["target_id"]))
    return out


def tracks_of(tree: xr.DataTree) -> xr.Dataset:
    """The /Processing/Tracks dataset (see :func:`track`).

    Raises
    ------
    DatasetError
        The dataset has no tracks (run :func:`track` first).
    """
    try:
        return tree[TRACKS_GROUP].ds
    except KeyError:
        raise DatasetError("the dataset has no /Processing/Tracks: run processing.track "
                           "(or `abacus track`) first") from None


#: per-track columns of ``abacus track --csv`` and --json, close to Echoview's fish-track export
#: (Target_ID, first/last ping, number of single targets, mean TS, speed and direction)
_CSV_COLUMNS = (("track_id", None), ("first_ping", "track_first_ping"), ("last_ping", "track_last_ping"),
                ("num_targets", "track_detections"), ("ts_mean_db", "track_ts"),
                ("speed_m_s", "track_speed"), ("velocity_x_m_s", "track_velocity_world_x"),
                ("velocity_y_m_s", "track_velocity_world_y"), ("velocity_z_m_s", "track_velocity_world_z"),
                ("heading_deg", None), ("in_counting_volume", "track_in_volume"),
                ("true_id", "track_true_id"), ("speed_error_m_s", "track_speed_error"),
                ("ts_error_db", "track_ts_error"))


def _per_track(ds):
    n = ds.sizes["track"]
    rows = []
    for i in range(n):
        row = {}
        for name, var in _CSV_COLUMNS:
            if name == "track_id":
                row[name] = i
            elif name == "heading_deg":
                # compass heading of the horizontal velocity: 0 = world +x (forward), 90 = +y
                vx, vy = float(ds["track_velocity_world_x"][i]), float(ds["track_velocity_world_y"][i])
                row[name] = _finite(np.degrees(np.arctan2(vy, vx)) % 360.0)
            elif var in ds:
                v = ds[var].values[i]
                if np.issubdtype(np.asarray(v).dtype, np.integer):
                    row[name] = int(v)
                else:
                    row[name] = float(v) if np.isfinite(v) else None
        rows.append(row)
    return rows


_INTEGER_SCORES = ("true_passages", "track_count_error", "tracks_following_a_fish", "num_switches",
                   "num_fragmentations", "mostly_tracked", "num_false_positives", "num_misses",
                   "num_unique_objects")


def _finite(v):
    """A float, or None where it is NaN or infinite (no value: JSON's null, CSV's empty cell)."""
    v = float(v)
    return v if np.isfinite(v) else None


def _nanmean(values):
    """The mean of the finite values, None when there are none."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else None


def _no_nan(obj):
    """``obj`` with every non-finite float (Python or numpy) replaced by None, numpy scalars by
    Python numbers."""
    if isinstance(obj, dict):
        return {k: _no_nan(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_no_nan(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj


def strict_json(obj) -> str:
    """``obj`` as strict JSON (RFC 8259): a value that is NaN or infinite is ``null``, never
    ``NaN`` or ``Infinity``, which JSON readers other than Python's refuse."""
    import json
    return json.dumps(_no_nan(obj), allow_nan=False)


def track_summary(tree: xr.DataTree) -> dict:
    """The tracks and their summary as plain Python (what ``abacus track --json`` prints).

    Returns
    -------
    dict
        ``tracks``: one dict per track (columns of :data:`_CSV_COLUMNS`: pings, number of
        detections, mean TS (dB re 1 m²), speed (m/s), world velocity (m/s), heading (deg, 0 =
        world +x), in the counting volume, and with truth the fish it follows and its errors);
        ``summary``: track count (passages through the counting volume), track density (m⁻³),
        the per-ping count's mean next to it when /Processing/Counts exists, and with truth the
        tracking scores: ``true_passages`` and ``counted_passages`` (the run's true and counted
        passages, what an nMAE over runs sums: Σ|counted − true| / Σ true), ``nmae`` (this
        run's |counted − true| / true), MOTA, MOTP, IDF1 and the others of py-motmetrics, and
        ``hota``, ``deta``, ``assa``, ``loca`` (processing/tracking/hota.py). A score without a
        value (NaN) is None.
    """
    ds = tracks_of(tree)
    a = ds.attrs
    s = {"tracks": int(ds.sizes["track"]), "track_count": int(a["track_count"]),
         "track_density_per_m3": _finite(a["track_density_per_m3"]),
         "counting_volume_m3": _finite(a["counting_volume_m3"]), "duration_s": _finite(a["duration_s"]),
         "method": str(a["method"])}
    c = group_of(tree, COUNTS_GROUP)
    if c is not None:
        if "count_after" in c and c["count_after"].size and np.isfinite(c["count_after"].values).any():
            s["per_ping_count_mean"] = _nanmean(c["count_after"].values)
            s["per_ping_density_per_m3"] = _nanmean(c["density_per_m3"].values)
        if "true_density_per_m3" in c and c["true_density_per_m3"].size:
            s["true_density_per_m3"] = _nanmean(c["true_density_per_m3"].values)
    for k in ("true_passages", "track_count_error", "tracks_following_a_fish", "mota", "motp", "idf1",
              "num_switches", "num_fragmentations", "mostly_tracked", "num_false_positives",
              "num_misses", "num_unique_objects", "hota", "deta", "assa", "loca", "speed_error_mean",
              "speed_error_sd", "ts_error_mean", "ts_error_sd"):
        if k in a:
            v = float(a[k])
            s[k] = None if not np.isfinite(v) else (int(v) if k in _INTEGER_SCORES else v)
    if "true_passages" in a:
        s["counted_passages"] = s["track_count"]
        s["nmae"] = _finite(a["count_nmae"]) if "count_nmae" in a else None
    return _no_nan({"tracks": _per_track(ds), "summary": s})


def format_tracks(result: dict) -> str:
    """Fixed-width per-track table and summary of :func:`track_summary` ('–': no value)."""
    def f(v, spec):
        if v is not None:
            return format(v, spec)
        width = "".join(ch for ch in spec.split(".")[0] if ch.isdigit())
        return format("–", f">{width}" if width else "")
    truth = "true_passages" in result["summary"]
    head = f"{'track':>5} {'pings':>9} {'dets':>5} {'TS (dB)':>8} {'speed':>6} {'head':>5} {'in':>3}"
    if truth:
        head += f" {'fish':>8} {'dspeed':>7} {'dTS':>6}"
    lines = [head]
    for t in result["tracks"]:
        line = (f"{t['track_id']:>5} {t['first_ping']:>4}–{t['last_ping']:<4} {t['num_targets']:>5} "
                f"{f(t['ts_mean_db'], '>8.1f')} {f(t['speed_m_s'], '>6.2f')} {f(t['heading_deg'], '>5.0f')} "
                f"{'yes' if t['in_counting_volume'] else 'no':>3}")
        if truth:
            fish = t.get("true_id")
            line += (f" {fish if fish is not None and fish >= 0 else '–':>8} "
                     f"{f(t.get('speed_error_m_s'), '>+7.2f')} {f(t.get('ts_error_db'), '>+6.1f')}")
        lines.append(line)
    s = result["summary"]
    lines.append("")
    lines.append(f"{s['tracks']} track(s) ({s['method']}); {s['track_count']} passage(s) through the counting "
                 f"volume ({f(s['counting_volume_m3'], '.2f')} m³) in {f(s['duration_s'], '.2f')} s; "
                 f"track density {f(s['track_density_per_m3'], '.4f')} m⁻³")
    if "per_ping_count_mean" in s:
        lines.append(f"per-ping counts beside it: {f(s['per_ping_count_mean'], '.2f')} per ping, density "
                     f"{f(s['per_ping_density_per_m3'], '.4f')} m⁻³")
    if "true_density_per_m3" in s:
        lines.append(f"true density of the counting volume: {f(s['true_density_per_m3'], '.4f')} m⁻³")
    if truth:
        lines.append(f"truth: {f(s['true_passages'], 'd')} fish passed through the volume (track count error "
                     f"{f(s.get('track_count_error'), '+d')}); IDF1 {f(s['idf1'], '.3f')}, MOTA {f(s['mota'], '.3f')}, "
                     f"MOTP {f(s['motp'], '.3f')} m, {f(s.get('num_switches'), 'd')} ID switch(es), "
                     f"{f(s.get('num_fragmentations'), 'd')} fragmentation(s)")
        lines.append(f"HOTA {f(s.get('hota'), '.3f')} (DetA {f(s.get('deta'), '.3f')}, AssA "
                     f"{f(s.get('assa'), '.3f')}, LocA {f(s.get('loca'), '.3f')}); count nMAE "
                     f"{f(s.get('nmae'), '.3f')} ({f(s.get('counted_passages'), 'd')} counted for "
                     f"{f(s.get('true_passages'), 'd')} true passages)")
        lines.append(f"per-track errors: speed {f(s['speed_error_mean'], '+.3f')} ± {f(s['speed_error_sd'], '.3f')} "
                     f"m/s, TS {f(s['ts_error_mean'], '+.2f')} ± {f(s['ts_error_sd'], '.2f')} dB")
    return "\n".join(lines)


def write_tracks_csv(tree: xr.DataTree, path):
    """Write one row per track (columns of :func:`track_summary`) as CSV, atomically."""
    import csv
    from pathlib import Path

    from processing.base.atomic import staged
    rows = track_summary(tree)["tracks"]
    keys = [name for name, var in _CSV_COLUMNS if var is None or var in tracks_of(tree)]
    path = Path(path)
    with staged(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            w.writerow(["" if r.get(k) is None else (f"{r[k]:.9g}" if isinstance(r[k], float) else r[k])
                        for k in keys])
    return path
