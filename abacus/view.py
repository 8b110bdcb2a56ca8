"""3-D view of a scene (pyvista): meshes, sonar and pose, transmit beam, counting volume, targets
(coloured inside / outside / shadowed) and a sample of reverberation ray hits; in a scene in
motion, the sonar at the ping's pose with its path over the run, and the tracks of moving
targets. Off-screen by default; an interactive window when asked for and a display exists.
World frame, z down."""
from __future__ import annotations

import os
import sys
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
    return grid.extract_surface(**_surface_algorithm(grid))


def _surface_algorithm(grid) -> dict:
    """The surface filter's algorithm named (pyvista ≥ 0.47 warns that its default will change;
    older releases have no such keyword)."""
    import inspect
    return ({"algorithm": "dataset_surface"}
            if "algorithm" in inspect.signature(grid.extract_surface).parameters else {})


def _window_probe_quiet(off_screen: bool):
    """Where ``off_screen`` and there is no X display (Linux), the making of the render window
    with VTK's log limited to errors: VTK tries an X window first, logs "bad X server
    connection" and goes on with EGL (or OSMesa), which is what an off-screen picture wants.
    Only the window's making is quietened; what VTK logs while drawing is shown. pyvista < 0.45
    (no ``vtk_verbosity``) logs as VTK does."""
    import contextlib

    import pyvista as pv
    headless = off_screen and sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if headless and hasattr(pv, "vtk_verbosity"):
        return pv.vtk_verbosity("error")
    return contextlib.nullcontext()


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
        t = draw_targets(setup.targets, p, setup.pose_at(p))
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


def _fill_window(plotter, points_w, view_w, *, legend_px=(330, 270), margin_px: int = 80):
    """Look at ``points_w`` (shape (n, 3), world frame) along ``-view_w`` so that they fill the
    window but the legend's top-right corner (``legend_px``: width, height): centred in what is
    left above or beside the legend and zoomed to it less ``margin_px`` on every side (the
    grid's labels); a scene much wider than tall on
    screen (a sideways fan along a swell) gets a window as short as it needs instead of a
    picture half empty."""
    cam, ren = plotter.camera, plotter.renderer
    pts = np.asarray(points_w, float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    lo, hi = pts.min(0), pts.max(0)
    centre = (lo + hi) / 2
    size = max(float(np.linalg.norm(hi - lo)), 1.0)
    cam.focal_point = centre
    cam.position = centre + 2.5 * size * view_w
    plotter.reset_camera(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))

    def display(p):
        ren.SetWorldPoint(*p, 1.0)
        ren.WorldToDisplay()
        return np.asarray(ren.GetDisplayPoint(), float)

    def projected():
        """Display (x, y) of every point, shape (n, 2): the camera's projection, vectorised."""
        w, h = plotter.window_size
        m = cam.GetCompositeProjectionTransformMatrix(w / h, -1, 1)
        a = np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])
        q = np.c_[pts, np.ones(len(pts))] @ a.T
        ndc = q[:, :2] / q[:, 3:4]
        return (ndc + 1) / 2 * [w, h]

    def world(x, y, depth):
        ren.SetDisplayPoint(x, y, depth)
        ren.DisplayToWorld()
        q = np.asarray(ren.GetWorldPoint(), float)
        return q[:3] / q[3]

    def move(shift):
        cam.focal_point = tuple(np.asarray(cam.focal_point) + shift)
        cam.position = tuple(np.asarray(cam.position) + shift)

    def frame(top, right):
        """Fit the points into the window less ``top`` pixels above and ``right`` to the right
        (the legend's); returns their extent on screen (pixels)."""
        w, h = plotter.window_size
        aw, ah = w - right, h - top
        for _ in range(4):                   # perspective: a few rounds settle it
            xy = projected()
            (x0, y0), (x1, y1) = xy.min(0), xy.max(0)
            cam.zoom(min((aw - 2 * margin_px) / max(x1 - x0, 1.0),
                         (ah - 2 * margin_px) / max(y1 - y0, 1.0)))
            xy = projected()
            (x0, y0), (x1, y1) = xy.min(0), xy.max(0)
            depth = display(cam.focal_point)[2]
            # the content's centre to the middle of the space the legend leaves
            move(world((x0 + x1) / 2, (y0 + y1) / 2, depth) - world(aw / 2, ah / 2, depth))
        xy = projected()
        return xy.max(0) - xy.min(0)

    # the legend above the picture (a wide scene) or beside it (a tall one): the larger picture
    w, h = plotter.window_size
    beside = frame(0, legend_px[0])
    above = frame(legend_px[1], 0)
    if beside[0] > above[0]:
        frame(0, legend_px[0])
    elif above[1] < 0.7 * (h - legend_px[1] - 2 * margin_px):     # wide and flat: shorter window
        plotter.window_size = [w, int(max(0.45 * w, legend_px[1] + above[1] + 2 * margin_px))]
        plotter.ren_win.SetSize(*plotter.window_size)
        frame(legend_px[1], 0)


def _into_built(view, x):
    return np.asarray(x, float) if view is None else view.to_world(np.asarray(x, float)[None])[0]


def render_scene(scene, output: str | Path | None = None, *, ping: int = 0, interactive: bool = False,
                 window_size=(1400, 1000)):
    """Draw the scene; write a PNG when ``output`` is given. Returns the output path (or None).

    Raises :class:`processing.base.extras.MissingExtra` without pyvista (the extra ``view``)."""
    from processing.base.extras import require
    pv = require("pyvista", "abacus view")

    from acoustics.simulation.setup import RunCache, counting_volume_of, make_setup
    from acoustics.targets.draw import draw_targets

    off = not (interactive and (os.environ.get("DISPLAY") or os.name == "nt"))
    setup = make_setup(scene)
    mount = setup.sonar.pose          # meshes are built in the sonar frame at rest
    pose = setup.pose_at(ping)
    to_world = pose.to_world
    with _window_probe_quiet(off):
        plotter = pv.Plotter(off_screen=off, window_size=list(window_size))
    plotter.set_background("white")
    rs, view = RunCache(setup).ray_scene_at(pose)
    if rs is not None:
        rs.advance(ping * setup.interval_s)        # the sea as this ping sees it
    colours = {"surface": "lightblue", "floor": "tan", "obstacle": "dimgray", "rigid": "gold",
               "pressure_release": "orange"}
    if rs is not None:
        from acoustics.paths.tiles import is_tiled
        for sm in (m for m in rs.meshes if not is_tiled(m.mesh)):     # a tiled floor: never whole
            v = (mount if view is not None else pose).to_world(sm.mesh.vertices)
            faces = np.hstack([np.full((len(sm.mesh.faces), 1), 3), sm.mesh.faces]).ravel()
            opacity = 0.35 if sm.role == "surface" else 0.9
            plotter.add_mesh(pv.PolyData(v, faces), color=colours.get(sm.role, "gray"),
                             opacity=opacity, ambient=0.55, diffuse=0.5, specular=0.0,
                             label=sm.name)
        if setup.effects.reverberation is not None:
            rs.reverberation(setup, ping, setup.seed, view)
            if len(rs.hit_sample):
                plotter.add_points(to_world(rs.hit_sample), color="saddlebrown", point_size=3,
                                   render_points_as_spheres=True, label="ray hits (sample)")
    # sonar: its arrays enlarged 10x so they show, and its axes
    origin = pose.position_m
    for arr, col in ((setup.sonar.transmitter, "red"), (setup.sonar.receiver.elements, "blue")):
        pts = to_world(arr.center_m * 10)
        plotter.add_points(pts, color=col, point_size=8, render_points_as_spheres=True)
    for axis, col, lab in ((0, "blue", "x_s (azimuth)"), (1, "green", "y_s (elevation)"), (2, "red", "boresight")):
        plotter.add_mesh(pv.Arrow(start=origin, direction=pose.rotation[:, axis], scale=2.5),
                         color=col, label=lab)
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
    t = draw_targets(setup.targets, ping, pose)
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
    content = [to_world(np.zeros((1, 3))), wedge.points, vol.points]
    if len(t):
        content.append(t.position_world_m)
    if rs is not None:
        for sm in (m for m in rs.meshes if not is_tiled(m.mesh)):   # where the beam reaches them
            v = (mount if view is not None else pose).to_world(sm.mesh.vertices)
            content.append(v[np.linalg.norm(v - origin, axis=1) <= 1.1 * r_end])
    content = np.concatenate(content)
    lo, hi = content.min(0), content.max(0)
    grid = plotter.show_grid(xtitle="x forward (m)", ytitle="y starboard (m)", ztitle="z depth (m)",
                             bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]), fmt="%.0f",
                             n_xlabels=4, n_ylabels=4, n_zlabels=4, location="outer")
    grid.SetCornerOffset(0.12)     # axes pulled back from their shared corners: no labels overlap
    # the grid's box and a margin for its labels in the picture
    box = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    arrows = origin + 2.5 * pose.rotation.T
    _fill_window(plotter, np.concatenate([content, box, arrows]), view_w)
    w, h = plotter.window_size
    plotter.add_legend(bcolor="white", size=(308 / w, 250 / h))       # the same size in pixels
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
