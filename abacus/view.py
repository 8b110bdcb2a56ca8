"""3-D view of a scene (pyvista): meshes, sonar and pose, transmit beam, counting volume, targets
(coloured inside / outside / shadowed) and a sample of reverberation ray hits; in a scene in
motion, the sonar at the ping's pose with its path over the run, and the tracks of moving
targets. Off-screen by default; an interactive window when asked for and a display exists.
World frame, z down."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from processing.base.atomic import staged

__all__ = ["render_scene"]


def _sector(r0, r1, half_az, half_el, n=24):
    """Surface of a sonar-frame sector (counting volume / beam wedge) as points and faces."""
    import pyvista as pv
    az = np.linspace(-half_az, half_az, n)
    el = np.linspace(-half_el, half_el, 3)
    pts = []
    for r in (r0, r1):
        for e in el:
            for a in az:
                pts.append([r * np.cos(e) * np.sin(a), r * np.sin(e), r * np.cos(e) * np.cos(a)])
    grid = pv.StructuredGrid()
    p = np.array(pts).reshape(2, 3, n, 3)
    grid.points = p.reshape(-1, 3)
    grid.dimensions = (n, 3, 2)
    return grid.extract_surface()


def _draw_motion(plotter, scene, setup, targets, max_tracks=300):
    """The sonar's path over the run and the tracks of moving targets (world frame)."""
    import pyvista as pv

    from acoustics.targets.draw import draw_targets
    pings = range(scene.pings.count)
    if setup.platform is not None and len(pings) > 1:
        path = np.array([setup.pose_at(p).position_m for p in pings])
        plotter.add_mesh(pv.lines_from_points(path), color="red", line_width=3, label="sonar path")
    if targets.velocity_world_m_s is None or not np.any(targets.velocity_world_m_s) or len(pings) < 2:
        return
    ids = targets.target_id[np.any(targets.velocity_world_m_s != 0, axis=1)][:max_tracks]
    tracks = {i: [] for i in ids.tolist()}
    for p in pings:
        t = draw_targets(scene, p, setup.pose_at(p))
        for i, xyz in zip(t.target_id.tolist(), t.position_world_m):
            if i in tracks:
                tracks[i].append(xyz)
    lines = [pv.lines_from_points(np.array(v)) for v in tracks.values() if len(v) > 1]
    if lines:
        merged = lines[0].merge(lines[1:]) if len(lines) > 1 else lines[0]
        few = len(lines) <= 10
        plotter.add_mesh(merged, color="royalblue", line_width=4 if few else 1.5,
                         opacity=1.0 if few else 0.6, label=f"target tracks ({len(pings)} pings)")


def _draw_bounces(plotter, rs, targets, view, built_pose, limit: int = 80):
    """The one-bounce specular paths off curved boundaries (a wavy sea): transmitter → bounce
    point → target, as lines, and the bounce points (the first ``limit``)."""
    import pyvista as pv
    rs.multipath(targets.position_sonar_m, np.ones(len(targets)), 1, view)
    lines, pts = [], []
    for _, start, sp, ok in rs.last_specular[:1]:          # the transmit legs
        for j in np.flatnonzero(ok)[:limit]:
            p = [start, sp.point_m[j], _into_built(view, targets.position_sonar_m[sp.pair[j]])]
            lines.append(built_pose.to_world(np.asarray(p)))
            pts.append(lines[-1][1])
    if not lines:
        return
    for k, seg in enumerate(lines):
        plotter.add_mesh(pv.lines_from_points(seg), color="purple", line_width=1.5,
                         label="surface bounce paths" if k == 0 else None)
    plotter.add_points(np.asarray(pts), color="purple", point_size=7,
                       render_points_as_spheres=True, label="bounce points")


def _into_built(view, x):
    return np.asarray(x, float) if view is None else view.to_world(np.asarray(x, float)[None])[0]


def render_scene(scene, output: str | Path | None = None, *, ping: int = 0, interactive: bool = False,
                 window_size=(1400, 1000)):
    """Draw the scene; write a PNG when ``output`` is given. Returns the output path (or None).

    Raises :class:`processing.base.extras.MissingExtra` without pyvista (the extra ``view``)."""
    from processing.base.extras import require
    pv = require("pyvista", "abacus view")

    from acoustics.simulation.setup import counting_volume_of, make_setup
    from acoustics.targets.draw import draw_targets

    off = not (interactive and (os.environ.get("DISPLAY") or os.name == "nt"))
    setup = make_setup(scene)
    mount = setup.sonar.pose          # meshes are built in the sonar frame at rest
    pose = setup.pose_at(ping)
    to_world = pose.to_world
    plotter = pv.Plotter(off_screen=off, window_size=list(window_size))
    plotter.set_background("white")
    rs, view = setup.ray_scene_at(scene, pose)
    if rs is not None:
        rs.advance(ping * setup.interval_s)        # the sea as this ping sees it
    colours = {"surface": "lightblue", "floor": "tan", "obstacle": "dimgray", "rigid": "gold",
               "pressure_release": "orange"}
    if rs is not None:
        for sm in rs.meshes:
            v = (mount if view is not None else pose).to_world(sm.mesh.vertices)
            faces = np.hstack([np.full((len(sm.mesh.faces), 1), 3), sm.mesh.faces]).ravel()
            opacity = 0.35 if sm.role == "surface" else 0.9
            plotter.add_mesh(pv.PolyData(v, faces), color=colours.get(sm.role, "gray"),
                             opacity=opacity, ambient=0.55, diffuse=0.5, specular=0.0,
                             label=sm.name)
        if scene.effects.reverberation.enabled:
            rs.reverberation(scene, setup, ping, scene.seed, view)
            if len(rs.hit_sample):
                plotter.add_points(to_world(rs.hit_sample), color="saddlebrown", point_size=3,
                                   render_points_as_spheres=True, label="ray hits (sample)")
    # sonar: its arrays enlarged 10x so they show, and its axes
    origin = pose.position_m
    for arr, col in ((setup.sonar.transmitter, "red"), (setup.sonar.receiver.elements, "blue")):
        pts = to_world(arr.center_m * 10)
        plotter.add_points(pts, color=col, point_size=8, render_points_as_spheres=True)
    for axis, col, lab in ((0, "blue", "x_s (azimuth)"), (1, "green", "y_s (elevation)"), (2, "red", "boresight")):
        plotter.add_mesh(pv.Arrow(origin, pose.rotation[:, axis], scale=2.5), color=col, label=lab)
    # transmit beam (10 dB wedge) and counting volume
    r_end = setup.counting_range_m[1] * 1.15
    from acoustics.sonar.beams import beamwidth
    tx = setup.sonar.transmitter
    kw = dict(medium=setup.medium, frequency_hz=scene.signal.center_frequency_hz)
    wedge = _sector(0.5, r_end, beamwidth(tx, plane="azimuth", level_db=-10, **kw) / 2,
                    beamwidth(tx, plane="elevation", level_db=-10, **kw) / 2)
    wedge.points = to_world(wedge.points)
    plotter.add_mesh(wedge, color="orange", opacity=0.12, label="transmit beam (10 dB)")
    r0, r1 = setup.counting_range_m
    vol = _sector(r0, r1, setup.tx_beamwidth_az_rad / 2, setup.tx_beamwidth_el_rad / 2, n=6)
    vol.points = to_world(vol.points)
    plotter.add_mesh(vol, color="green", opacity=0.25, label="counting volume")
    plotter.add_mesh(vol.extract_feature_edges(), color="darkgreen", line_width=2)
    # targets of one ping
    t = draw_targets(scene, ping, pose)
    if len(t):
        inside = counting_volume_of(setup, t.position_sonar_m)
        shadow = rs.shadowed(t.position_sonar_m, view) if rs is not None else np.zeros(len(t), bool)
        for sel, col, lab in ((inside & ~shadow, "limegreen", "targets inside"),
                              (~inside & ~shadow, "black", "targets outside"),
                              (shadow, "red", "targets shadowed")):
            if sel.any():
                plotter.add_points(t.position_world_m[sel], color=col,
                                   point_size=14 if col == "red" else 10,
                                   render_points_as_spheres=True, label=lab)
    if rs is not None and len(t) and scene.effects.max_bounces > 0 and rs.curved:
        _draw_bounces(plotter, rs, t, view, mount if view is not None else pose)
    _draw_motion(plotter, scene, setup, t)
    plotter.add_legend(bcolor="white", size=(0.22, 0.25))
    plotter.show_grid(xtitle="x forward (m)", ytitle="y starboard (m)", ztitle="z depth (m)")
    # a vertical fan (down-looking sonar) is seen square-on from aft of it and a little above; a
    # horizontal fan (sideways-looking sonar) from its port side at its own depth, so that the
    # surface, the sonar and the targets' depths show; depth always increases down the screen
    focus = to_world(np.array([0.0, 0.0, 0.45 * r1]))
    span = max(r1, 10.0)
    x_w, y_w, z_w = pose.rotation[:, 0], pose.rotation[:, 1], pose.rotation[:, 2]
    up = np.array([0.0, 0.0, -1.0])
    if abs(y_w[2]) < 0.7:
        view_w = y_w + 0.45 * x_w - 0.35 * z_w + 0.35 * up
    else:
        view_w = -x_w - 0.5 * z_w + 0.1 * up
    view_w = view_w / np.linalg.norm(view_w)
    if len(t) and t.velocity_world_m_s is not None:
        # targets moving along the line of sight would show as dots: look across their motion
        d = np.array([*np.mean(t.velocity_world_m_s[:, :2], axis=0), 0.0])
        if np.linalg.norm(d) > 1e-9 and abs(view_w @ d) > 0.7 * np.linalg.norm(d):
            side = np.cross(up, d / np.linalg.norm(d)) * np.hypot(view_w[0], view_w[1])
            view_w = side + view_w                 # half-way round: the fan and the tracks show
            view_w = view_w / np.linalg.norm(view_w)
    plotter.camera.focal_point = focus
    plotter.camera.position = focus + 2.9 * span * view_w
    plotter.camera.up = tuple(up)
    out = None
    if output is not None:
        out = Path(output)
        out.parent.mkdir(parents=True, exist_ok=True)
        with staged(out, suffix=".png") as tmp:
            plotter.screenshot(str(tmp))
    if not off:
        plotter.show()
    plotter.close()
    return out
