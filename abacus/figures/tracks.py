"""Figures of fish tracks: the tracks in 3-D and seen from above and from the side, over the
counting volume, with the true fish paths where the dataset has them (matplotlib, Agg)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from processing.base.dataset import TRUTH_GROUP
from abacus.figures.plots import fixed_layout, save

__all__ = ["track_figures", "volume_outline_m"]


def volume_outline_m(range_m, azimuth_halfwidth_rad, elevation_halfwidth_rad, n: int = 24):
    """Points on the surface of a counting volume (sonar frame).

    Parameters
    ----------
    range_m : (float, float)
    azimuth_halfwidth_rad, elevation_halfwidth_rad : float
    n : int
        Points per edge.

    Returns
    -------
    ndarray, shape (m, 3)
        Sonar-frame points (m) on the volume's faces (azimuth θ = atan2(x, z), elevation
        φ = atan2(y, √(x² + z²)), docs/conventions.md): their convex hull in any projection is the
        volume's outline there.
    """
    r = np.linspace(*range_m, n)
    th = np.linspace(-azimuth_halfwidth_rad, azimuth_halfwidth_rad, n)
    ph = np.linspace(-elevation_halfwidth_rad, elevation_halfwidth_rad, n)
    pts = []
    for rr in (r[0], r[-1]):
        T, P = np.meshgrid(th, ph)
        pts.append(np.stack([T.ravel(), P.ravel(), np.full(T.size, rr)], -1))
    for tt in (th[0], th[-1]):
        R, P = np.meshgrid(r, ph)
        pts.append(np.stack([np.full(R.size, tt), P.ravel(), R.ravel()], -1))
    for pp in (ph[0], ph[-1]):
        R, T = np.meshgrid(r, th)
        pts.append(np.stack([T.ravel(), np.full(R.size, pp), R.ravel()], -1))
    tpr = np.concatenate(pts)
    t, p, rr = tpr[:, 0], tpr[:, 1], tpr[:, 2]
    return np.stack([rr * np.cos(p) * np.sin(t), rr * np.sin(p), rr * np.cos(p) * np.cos(t)], -1)


def _hull(ax, pts2, **kw):
    from scipy.spatial import ConvexHull, QhullError
    try:
        h = ConvexHull(pts2)
    except (QhullError, ValueError):
        return
    v = np.r_[h.vertices, h.vertices[:1]]
    ax.plot(pts2[v, 0], pts2[v, 1], **kw)


def track_figures(tree, outdir: Path) -> list[Path]:
    """tracks.png: the tracks of /Processing/Tracks in 3-D (world frame), seen from above (x–y)
    and from the side along each axis of the fan (x–z, y–z), the counting volume outlined at the
    first ping's pose; tracks through the volume in colour, the others thin grey; true paths of
    the fish that passed through it dashed. track_ts.png: each counted track's mean TS with the
    spread of its detections' TS, against the true fish's TS where the dataset has it, and the
    histogram of the detections' TS (:func:`_track_ts_figure`).

    Returns
    -------
    list of Path
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from processing.pipeline import pose_of
    from processing.tracking.tracks import tracks_of

    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    ds = tracks_of(tree)
    a = ds.attrs
    pt = ds["point_track"].values.astype(int)
    xyz = np.stack([ds[f"point_world_{c}"].values for c in "xyz"], -1)
    det = ds["point_detection"].values >= 0
    counted = ds["track_in_volume"].values.astype(bool)
    outline = volume_outline_m(tuple(np.asarray(a["counting_range_m"], float)),
                               float(a["counting_azimuth_halfwidth_rad"]),
                               float(a["counting_elevation_halfwidth_rad"]))
    pose = pose_of(tree)
    if pose is not None:
        pos, rot = (np.asarray(v, float) for v in pose)
        if rot.ndim == 3:
            pos, rot = pos[0], rot[0]
        outline = outline @ rot.T + pos
    truth = None
    if TRUTH_GROUP in tree.children:
        gt = tree[TRUTH_GROUP].ds
        if "target_id" in gt and "target_in_counting_volume" in gt:
            ids = gt["target_id"].values
            passed = np.unique(ids[gt["target_in_counting_volume"].values.astype(bool)])
            tw = np.stack([gt[f"target_world_{c}"].values for c in "xyz"], -1)
            truth = [tw[ids == f] for f in passed]
    colours = plt.get_cmap("tab20")
    fig = plt.figure(figsize=(15, 10))
    fixed_layout(fig, left=0.7, right=0.3, bottom=0.6, top=0.5, wspace=0.3, hspace=0.3)
    ax3 = fig.add_subplot(2, 2, 1, projection="3d")
    views = [(fig.add_subplot(2, 2, 2), 0, 1, "seen from above (x–y)"),
             (fig.add_subplot(2, 2, 3), 0, 2, "seen from the side (x–z)"),
             (fig.add_subplot(2, 2, 4), 1, 2, "seen from the side (y–z)")]
    lim = np.r_[outline, xyz[counted[pt]]] if counted.any() else outline
    lo, hi = lim.min(0), lim.max(0)
    pad = 0.15 * (hi - lo).max() + 0.2
    for i in range(ds.sizes["track"]):
        k = pt == i
        style = (dict(color=colours(i % 20), lw=1.6) if counted[i] else dict(color="0.75", lw=0.7))
        ax3.plot(xyz[k, 0], xyz[k, 1], xyz[k, 2], **style)
        for ax, u, v, _ in views:
            ax.plot(xyz[k, u], xyz[k, v], **style)
            if counted[i]:
                m = k & det
                ax.plot(xyz[m, u], xyz[m, v], ".", color=style["color"], ms=3)
    if truth is not None:
        for j, path in enumerate(truth):
            lab = dict(label="true path of a fish that passed") if j == 0 else {}
            for ax, u, v, _ in views:
                ax.plot(path[:, u], path[:, v], "--", color="k", lw=0.6, **lab)
                lab = {}
    for ax, u, v, title in views:
        _hull(ax, outline[:, [u, v]], color="k", lw=1.0)
        ax.set_xlim(lo[u] - pad, hi[u] + pad)
        ax.set_ylim(lo[v] - pad, hi[v] + pad)
        ax.set_xlabel(f"world {'xyz'[u]} (m)")
        ax.set_ylabel(f"world {'xyz'[v]} (m)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        if v == 2:
            ax.invert_yaxis()               # depth grows downwards
    if truth is not None:
        views[0][0].legend(fontsize=8, loc="upper left")
    ax3.plot(*outline[::7].T, ",", color="k", alpha=0.3)
    ax3.set_xlabel("world x (m)")
    ax3.set_ylabel("world y (m)")
    ax3.set_zlabel("depth z (m)")
    ax3.invert_zaxis()
    title = (f"{ds.sizes['track']} tracks, {int(a['track_count'])} through the counting volume "
             f"(outlined)")
    if "true_passages" in a:
        title += f"; {int(a['true_passages'])} true passages, IDF1 {float(a['idf1']):.2f}"
    ax3.set_title(title, fontsize=9)
    paths = [save(fig, outdir / "tracks.png")]
    plt.close(fig)
    paths.append(_track_ts_figure(ds, counted, colours, outdir))
    return paths


def _track_ts_figure(ds, counted, colours, outdir: Path) -> Path:
    """track_ts.png: left, one row per counted track (in order of first ping): its mean TS
    (σ_bs averaged in the linear domain, the dataset's ``track_ts``) with the 10–90 % range of its
    detections' beam-compensated TS as a bar, the number of detections, and the true fish's TS
    (``track_ts`` − ``track_ts_error``) where scored; right, the histogram of every detection's
    TS on the counted tracks and of the tracks' means."""
    import matplotlib.pyplot as plt

    pt = ds["point_track"].values.astype(int)
    ts = ds["point_ts_comp"].values
    mean = ds["track_ts"].values
    err = ds["track_ts_error"].values if "track_ts_error" in ds else None
    first = ds["track_first_ping"].values
    rows = [i for i in np.flatnonzero(counted) if np.isfinite(mean[i])]
    rows.sort(key=lambda i: (first[i], i))
    fig, (ax, hx) = plt.subplots(1, 2, figsize=(12, max(4.5, 1.6 + 0.22 * len(rows))),
                                 gridspec_kw={"width_ratios": [3, 2]})
    fixed_layout(fig, left=1.3, right=0.3, top=0.45, bottom=1.4, wspace=0.25)
    every, ends = [], []
    for y, i in enumerate(rows):
        v = ts[(pt == i) & np.isfinite(ts)]
        every.append(v)
        lo, hi = np.percentile(v, [10, 90])
        ends += [lo, hi, mean[i]] + ([mean[i] - err[i]] if err is not None else [])
        c = colours(i % 20)
        ax.plot([lo, hi], [y, y], "-", color=c, lw=2.5, alpha=0.6, solid_capstyle="butt")
        ax.plot(mean[i], y, "o", color=c, ms=6)
        if err is not None and np.isfinite(err[i]):
            ax.plot(mean[i] - err[i], y, "k|", ms=11, mew=1.5)
        ax.annotate(f"{v.size}", (max(hi, mean[i]), y), xytext=(4, 0), textcoords="offset points", va="center",
                    fontsize=7, color="0.35")
    ax.set_yticks(range(len(rows)), [f"{i} (pings {first[i]}–{ds['track_last_ping'].values[i]})"
                                     for i in rows], fontsize=7)
    ax.set_ylim(len(rows) - 0.5, -0.5)          # the first track on top, as a list reads
    ax.set_ylabel("track (first–last ping)")
    ax.set_xlabel("TS, beam-compensated (dB re 1 m²)")
    ax.grid(alpha=0.3, axis="x")
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], marker="o", ls="", color="0.3", label="track mean (σ_bs averaged)"),
               Line2D([], [], lw=2.5, color="0.3", alpha=0.6, label="10–90 % of its detections"),
               Line2D([], [], ls="", marker="$n$", color="0.35", label="number of detections")]
    if err is not None:
        handles.append(Line2D([], [], marker="|", ls="", color="k", ms=11, mew=1.5,
                              label="true TS of the fish it follows"))
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2)
    ends = np.asarray(ends, float)
    if np.isfinite(ends).any():
        ax.set_xlim(np.nanmin(ends) - 1.0, np.nanmax(ends) + 2.0)    # room for the counts
    ax.set_title(f"TS of the {len(rows)} tracks through the counting volume")
    allts = np.concatenate(every) if every else np.zeros(0)
    if allts.size:
        bins = np.arange(np.floor(allts.min()), np.ceil(allts.max()) + 1.0, 1.0)
        hx.hist(allts, bins=bins, color="0.6", label=f"detections on them ({allts.size})")
        hx.hist(mean[rows], bins=bins, color="tab:blue", alpha=0.8, label=f"track means ({len(rows)})")
        hx.legend(fontsize=8)
    hx.set_xlabel("TS, beam-compensated (dB re 1 m²)")
    hx.set_ylabel("number (per 1 dB)")
    hx.set_title("TS histogram, tracks through the counting volume")
    hx.grid(alpha=0.3)
    path = save(fig, outdir / "track_ts.png")
    plt.close(fig)
    return path
