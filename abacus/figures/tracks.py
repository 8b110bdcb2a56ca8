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
    the fish that passed through it dashed. track_ts.png: per-point compensated TS along each
    counted track.

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
    views = [(fig.add_subplot(2, 2, 2), 0, 1, "seen from above"),
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
    fig, ax = plt.subplots(figsize=(10, 4.5))
    fixed_layout(fig, left=0.8)
    ts = ds["point_ts_comp"].values
    ping = ds["point_ping_index"].values
    for i in np.flatnonzero(counted):
        k = (pt == i) & np.isfinite(ts)
        ax.plot(ping[k], ts[k], ".-", color=colours(i % 20), lw=0.8, ms=4)
    ax.set_xlabel("ping index")
    ax.set_ylabel("TS, beam-compensated (dB re 1 m²)")
    ax.set_title("per-ping TS along the tracks through the counting volume")
    ax.grid(alpha=0.3)
    paths.append(save(fig, outdir / "track_ts.png"))
    plt.close(fig)
    return paths
