"""Pictures and numbers of the scenes in motion (docs/scenes.md, "Scenes in motion").

    python benchmarks/motion_scenes.py            # all three scenes
    python benchmarks/motion_scenes.py fish_passing

For each scene: its `abacus view` picture at one ping (docs/figures/scene_<name>.png), fan
images at a few pings with the ground truth marked, and the numbers docs/scenes.md quotes
(printed). Fan images are in dB re the brightest cell of the pings shown, so they compare.
"""
from __future__ import annotations

import sys
import warnings

import numpy as np
from _report import ROOT

from processing.base.dataset import TRUTH_GROUP

import acoustics
import processing
from acoustics import SceneWarning, load_scene
from abacus.figures.plots import fan_beam, fixed_layout, save

FIGURES = ROOT / "docs" / "figures"


def _load(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        return load_scene(ROOT / "scenes" / f"{name}.yaml")


def _run(scene):
    tree = processing.count(acoustics.simulate(scene), images="full")
    return tree, processing.images_of(tree), processing.detections_of(tree)


def _truth(tree):
    gt = tree[TRUTH_GROUP].ds
    return {k: gt[k].values for k in gt.data_vars}


def _fans(images, pings, titles, path, *, truth=None, dynamic_range_db=50.0, detections=None,
          zlim=None, width=3.4, height=4.6):
    """One fan image per ping, side by side, in dB re the brightest of them; ``zlim``: the
    along-boresight span shown (m)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    mag = np.abs(images.image[list(pings), 0])
    ref = float(mag.max())
    fig, axes = plt.subplots(1, len(pings), figsize=(width * len(pings) + 1.0, height), squeeze=False)
    fixed_layout(fig, left=0.8, right=1.3, wspace=0.25, bottom=0.55, top=0.45)
    for ax, m, p, title in zip(axes[0], mag, pings, titles):
        x, z, img, inside = fan_beam(m, images.range_m, images.beam_angle_rad, with_mask=True,
                                     pixel_m=0.03)
        db = np.ma.masked_where(~inside, 20 * np.log10(np.maximum(img, ref * 1e-6) / ref))
        im = ax.imshow(db, origin="lower", extent=(x[0], x[-1], z[0], z[-1]), cmap="viridis",
                       vmin=-dynamic_range_db, vmax=0, interpolation="nearest", aspect="equal")
        if zlim is not None:
            ax.set_ylim(*zlim)
        ax.invert_yaxis()                      # depth down, as the sonar looks
        if detections is not None:
            k = detections["ping"].values == p
            ax.plot(detections["x_m"].values[k], detections["z_m"].values[k], "o", mfc="none",
                    mec="white", ms=7, mew=0.8, label="detections")
        if truth is not None:
            k = (truth["target_ping_index"] == p) & (truth["target_in_counting_volume"] == 1)
            ax.plot(truth["target_x"][k], truth["target_z"][k], "+", color="red", ms=8, mew=1.4,
                    label="true, in the 3 dB fan", zorder=5)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("x_s, across the fan (m)")
    axes[0, 0].set_ylabel("z_s, along the boresight (m)")
    if truth is not None or detections is not None:
        axes[0, 0].legend(loc="lower left", fontsize=7, framealpha=0.8)
    cax = fig.add_axes([1 - 1.05 / fig.get_size_inches()[0], 0.2, 0.15 / fig.get_size_inches()[0], 0.6])
    fig.colorbar(im, cax=cax).set_label("|I| (dB re max)")
    save(fig, path)
    plt.close(fig)


def _view(scene, name, ping):
    from abacus.view import render_scene
    render_scene(scene, FIGURES / f"scene_{name}.png", ping=ping, window_size=(1200, 850))


# ------------------------------------------------------------------ the scenes
def fish_passing():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scene = _load("fish_passing")
    tree, images, det = _run(scene)
    t = _truth(tree)
    interval = scene.pings.interval_s
    n = scene.pings.count
    # the strongest detection of each ping is the fish; its interferometric elevation and level
    el, amp, el_true, r_true = (np.full(n, np.nan) for _ in range(4))
    for p in range(n):
        k = det["ping"].values == p
        if k.any():
            i = int(np.argmax(det["amplitude"].values[k]))
            el[p] = det["elevation_rad"].values[k][i]
            amp[p] = det["amplitude"].values[k][i]
        j = t["target_ping_index"] == p
        el_true[p] = t["target_elevation"][j][0]
        r_true[p] = t["target_range"][j][0]
    time = np.arange(n) * interval
    # in the 3 dB fan (|φ| < 0.43°) the measured elevation falls at v / r: fit it
    half = np.radians(float(tree["Sonar"]["beamwidth_transmit_minor"])) / 2
    inb = np.abs(el_true) < 1.5 * half
    slope = np.polyfit(time[inb], el[inb], 1)[0]
    speed = -slope * np.mean(r_true[inb])
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    fixed_layout(fig, left=0.7, right=0.2, wspace=0.45, bottom=0.55, top=0.35)
    a1.plot(time, np.degrees(el_true), "k-", label="true elevation")
    a1.plot(time, np.degrees(el), "o", mfc="none", label="interferometric (strongest detection)")
    a1.axhspan(-np.degrees(half), np.degrees(half), color="orange", alpha=0.2, label="3 dB fan")
    a1.set_xlabel("time (s)")
    a1.set_ylabel("elevation φ (deg)")
    a1.set_title(f"speed from the elevation track: {speed:.3f} m/s (true 0.5)", fontsize=9)
    a1.legend(fontsize=7)
    a1.grid(alpha=0.3)
    a2.plot(time, 20 * np.log10(amp / np.nanmax(amp)), "o-", ms=4)
    a2.set_xlabel("time (s)")
    a2.set_ylabel("peak |I| (dB re max)")
    a2.set_title("its echo through the transmit beam", fontsize=9)
    a2.grid(alpha=0.3)
    save(fig, FIGURES / "fish_passing_track.png")
    plt.close(fig)
    pings = (4, 10, 16)
    _fans(images, pings, [f"ping {p}, t = {p * interval:.1f} s, φ = {np.degrees(el_true[p]):+.2f}°"
                          for p in pings], FIGURES / "fish_passing_fans.png", truth=t, detections=det,
          zlim=(16.5, 19.5), width=4.2, height=3.2)
    _view(scene, "fish_passing", 10)
    ok = np.isfinite(el) & inb
    print(f"fish_passing: speed from the interferometric elevation track {speed:.4f} m/s (true 0.5); "
          f"elevation error in the fan: rms {np.degrees(np.sqrt(np.mean((el - el_true)[ok] ** 2))):.4f}°, "
          f"{ok.sum()} pings; peak level spread {20 * np.log10(np.nanmax(amp) / np.nanmin(amp)):.1f} dB; "
          f"TS {t['target_ts'].min():.1f}..{t['target_ts'].max():.1f} dB")


def migrating_school():
    scene = _load("migrating_school")
    tree, images, det = _run(scene)
    t = _truth(tree)
    c = processing.counts_of(tree)
    interval = scene.pings.interval_s
    pings = (8, 14, 20, 26)
    _fans(images, pings, [f"ping {p}, t = {p * interval:.0f} s" for p in pings],
          FIGURES / "migrating_school_fans.png", truth=t, dynamic_range_db=40.0)
    _view(scene, "migrating_school", 14)
    n = scene.pings.count
    x = np.array([t["target_world_x"][t["target_ping_index"] == p].mean() for p in range(n)])
    inside = c["true_in_volume"].values
    h = np.arctan2(t["target_velocity_world_y"], t["target_velocity_world_x"])
    r_first = abs(np.mean(np.exp(1j * h[t["target_ping_index"] == 0])))
    r_last = abs(np.mean(np.exp(1j * h[t["target_ping_index"] == n - 1])))
    print(f"migrating_school: centroid x {x[0]:.2f} → {x[-1]:.2f} m over {(n - 1) * interval:.1f} s "
          f"({(x[-1] - x[0]) / ((n - 1) * interval):.3f} m/s along x); polarisation {r_first:.3f} → "
          f"{r_last:.3f}; fish in the counting volume per ping: max {inside.max()}, pings with any "
          f"{int((inside > 0).sum())}; counted after interferometry {c['count_after'].values.mean():.2f} "
          f"per ping vs true {inside.mean():.2f}; TS {np.median(t['target_ts']):.1f} dB median; "
          f"densities: volume {np.nanmean(c['density_per_m3'].values):.3f}, occupied "
          f"{np.nanmean(c['occupied_density_per_m3'].values):.3f} m⁻³")


def rolling_swell():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scene = _load("rolling_swell")
    tree, images, det = _run(scene)
    t = _truth(tree)
    plat = tree["Platform"].ds
    roll = plat["roll"].values
    interval = scene.pings.interval_s
    n = scene.pings.count
    # the middle target (18 m down): the detection nearest its true range in each ping
    az, az_true, wy = (np.full(n, np.nan) for _ in range(3))
    for p in range(n):
        j = (t["target_ping_index"] == p) & (t["target_id"] == 1)
        r0 = t["target_range"][j][0]
        az_true[p] = t["target_azimuth"][j][0]
        k = (det["ping"].values == p) & (np.abs(det["range_m"].values - r0) < 0.1)
        if k.any():
            i = int(np.argmax(det["amplitude"].values[k]))
            az[p] = det["azimuth_rad"].values[k][i]
            wy[p] = det["world_y_m"].values[k][i]
    time = np.arange(n) * interval
    c = scene.medium.sound_speed_m_s
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    fixed_layout(fig, left=0.7, right=0.2, wspace=0.45, bottom=0.55, top=0.35)
    a1.plot(time, roll, "k-", label="roll (deg)")
    a1.plot(time, np.degrees(az), "o", mfc="none", label="azimuth of the 18 m target")
    a1.set_xlabel("time (s)")
    a1.set_ylabel("deg")
    a1.legend(fontsize=7)
    a1.grid(alpha=0.3)
    a1.set_title("the image turns with the roll", fontsize=9)
    a2.plot(time, wy * 100, "o", mfc="none")
    a2.set_xlabel("time (s)")
    a2.set_ylabel("located world y (cm)")
    a2.set_title("located in the world through each ping's pose", fontsize=9)
    a2.grid(alpha=0.3)
    save(fig, FIGURES / "rolling_swell_track.png")
    plt.close(fig)
    k = np.isfinite(az)
    # the receive leg's pose is the one at the echo's arrival, 2r/c after transmission
    lag = np.array([np.degrees(scene.sonar.motion.swell.roll_amplitude) * 2 * np.pi
                    / scene.sonar.motion.swell.roll_period_s
                    * np.cos(2 * np.pi * tt / scene.sonar.motion.swell.roll_period_s) * 2 * 18.5 / c
                    for tt in time])
    pings = (12, 0, 4)                         # roll −5°, 0°, +5°
    _fans(images, pings, [f"ping {p}, roll {roll[p]:+.1f}°, pitch {plat['pitch'].values[p]:+.2f}°"
                          for p in pings], FIGURES / "rolling_swell_fans.png", truth=t)
    _view(scene, "rolling_swell", 4)
    print(f"rolling_swell: middle target found in {k.sum()} of {n} pings; azimuth − roll: rms "
          f"{np.degrees(np.sqrt(np.mean((az - np.radians(roll))[k] ** 2))):.3f}°, vs true azimuth rms "
          f"{np.degrees(np.sqrt(np.mean((az - az_true)[k] ** 2))):.3f}°; turn in flight up to "
          f"{np.abs(lag).max():.3f}°; located world y rms {np.sqrt(np.nanmean(wy[k] ** 2)) * 100:.1f} cm")


def _fermat_1d(src, dst, waves, t, x_lo, x_hi):
    """Every bounce point of src → surface → dst on the swell z = −Σ a cos(kx − ωt + ϕ) (world
    x–z plane, deep water), by scipy's brentq on dφ/dx: [(x, path length)]."""
    from scipy.optimize import brentq
    g = 9.81

    def z_and_slope(x):
        z = dz = 0.0
        for a, lam, _, ph in waves:
            k = 2 * np.pi / lam
            arg = k * x - np.sqrt(g * k) * t + np.radians(ph)
            z -= a * np.cos(arg)
            dz += a * k * np.sin(arg)
        return z, dz

    def dphi(x):
        z, dz = z_and_slope(x)
        return sum(((x - q[0]) + (z - q[2]) * dz) / np.hypot(x - q[0], z - q[2]) for q in (src, dst))

    xs = np.linspace(x_lo, x_hi, 2001)
    f = np.array([dphi(x) for x in xs])
    out = []
    for i in np.flatnonzero(f[:-1] * f[1:] < 0):
        x = brentq(dphi, xs[i], xs[i + 1], xtol=1e-12)
        z, _ = z_and_slope(x)
        out.append((x, np.hypot(x - src[0], z - src[2]) + np.hypot(x - dst[0], z - dst[2])))
    return out


def swell_ghost():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scene = _load("swell_ghost")
    tree, images, det = _run(scene)
    t = _truth(tree)
    n, interval = scene.pings.count, scene.pings.interval_s
    waves = [(w.amplitude_m, w.wavelength_m, w.direction_deg, w.phase_deg)
             for w in scene.boundaries[0].mesh.waves]
    sonar = np.asarray(scene.sonar.pose.position_m, float)
    target = np.array([20.0, 0.0, 2.0])
    direct = np.linalg.norm(target - sonar)
    beam = int(np.argmin(np.abs(images.beam_angle_rad)))
    rng_m = images.range_m
    found, predicted = [], []
    for p in range(n):
        paths = _fermat_1d(sonar, target, waves, p * interval, 1.0, 19.5)
        bounce = max(paths, key=lambda q: -q[1])[1] if paths else np.nan   # the shortest
        predicted.append(((direct + bounce) / 2, bounce / 2 + bounce / 2))
        col = np.abs(images.image[p, 0][:, beam])
        peaks = [i for i in range(1, len(col) - 1) if col[i] >= col[i - 1] and col[i] > col[i + 1]
                 and col[i] > 0.01 * col.max() and rng_m[i] > direct + 0.1]
        # parabolic interpolation of each peak's range
        rr = []
        for i in peaks:
            a, b, c = np.log(col[i - 1:i + 2])
            rr.append(rng_m[i] + 0.5 * (a - c) / (a - 2 * b + c) * (rng_m[1] - rng_m[0]))
        found.append(rr)
    time = np.arange(n) * interval
    pred = np.array(predicted)
    fig, ax = plt.subplots(figsize=(7.5, 3.8))
    fixed_layout(fig, left=0.8, right=0.2, bottom=0.55, top=0.35)
    ax.plot(time, pred[:, 0], "k-", lw=1, label="Tx→surface→target→Rx and back (analytic)")
    ax.plot(time, pred[:, 1], "k--", lw=1, label="surface both ways (analytic)")
    for p, rr in enumerate(found):
        ax.plot([time[p]] * len(rr), rr, "o", mfc="none", color="C1",
                label="image peaks behind the target (> −40 dB)" if p == 0 else None)
    ax.axhline(direct, color="C0", lw=0.8, label="direct echo")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("range (m)")
    ax.set_title("surface ghosts of a target 2 m under a 0.5 m, 25 m swell", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(alpha=0.3)
    save(fig, FIGURES / "swell_ghost_ranges.png")
    plt.close(fig)
    err, missing = [], 0
    for p, rr in enumerate(found):
        for r in pred[p]:
            d = min(abs(np.array(rr) - r)) if rr else np.inf
            if d < 0.05:
                err.append(d)
            else:
                missing += 1
    pings = (0, 4, 8)
    _fans(images, pings, [f"ping {p}, t = {p * interval:.2f} s" for p in pings],
          FIGURES / "swell_ghost_fans.png", truth=t, dynamic_range_db=40.0)
    _view(scene, "swell_ghost", 4)
    print(f"swell_ghost: ghost ranges swing {np.ptp(pred[:, 0]) * 100:.1f} cm (one bounce) and "
          f"{np.ptp(pred[:, 1]) * 100:.1f} cm (two); image peaks within "
          f"{np.median(err) * 1000:.1f} mm median, {np.max(err) * 1000:.1f} mm worst of the "
          f"analytic ranges ({len(err)} found, {missing} of {2 * n} under −40 dB re the ping's "
          f"peak or merged)")


def pelagic_wind_sea():
    scene = _load("pelagic_wind_sea")
    tree, images, det = _run(scene)
    t = _truth(tree)
    pings = (0, 4, 8)
    _fans(images, pings, [f"ping {p}, t = {p * scene.pings.interval_s:.1f} s" for p in pings],
          FIGURES / "pelagic_wind_sea_fans.png", truth=t, dynamic_range_db=50.0)
    _view(scene, "pelagic_wind_sea", 4)
    cnt = tree["Processing/Counts"].ds if "Processing/Counts" in tree else None
    print(f"pelagic_wind_sea: {len(det['ping'])} detections in {scene.pings.count} pings")


SCENES = {"fish_passing": fish_passing, "migrating_school": migrating_school,
          "rolling_swell": rolling_swell, "swell_ghost": swell_ghost,
          "pelagic_wind_sea": pelagic_wind_sea}

if __name__ == "__main__":
    for name in sys.argv[1:] or SCENES:
        SCENES[name]()
