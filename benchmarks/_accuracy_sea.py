"""Accuracy vs cost of the wavy sea's knobs (sections of docs/accuracy.md, registered by
benchmarks/accuracy.py): the surface mesh resolution, the refinement of bounce points, and the
cost of the specular search on a mesh of 10⁵ facets."""
from __future__ import annotations

import time

import numpy as np
from _report import best_time, table

# a short swell of three waves: its content does not change with the mesh (a wind sea's would:
# the grid's Nyquist cuts its spectrum), so the rows show the mesh's error alone
WAVES = [(0.25, 12.0, 0.0, 0.0), (0.12, 7.0, 25.0, 40.0), (0.06, 4.5, -30.0, 100.0)]
SONAR = np.array([0.0, 0.0, 4.0])          # world, z down


def _targets(n=40, seed=7):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(8, 24, n), rng.uniform(-4, 4, n), rng.uniform(1.0, 6.0, n)])


def _paths(resolution, newton=8, time_s=1.3, exact=False):
    from acoustics.paths.meshes import _grid_mesh
    from acoustics.paths.sea_surface import swell
    from acoustics.paths.specular import specular_points
    s = swell(components=WAVES, center_m=(14.0, 0.0), size_m=(32.0, 14.0), resolution_m=resolution)
    v, n = s.grid(time_s)
    m = _grid_mesh(s.x_m, s.y_m, v[:, 2].reshape(s.y_m.size, s.x_m.size))
    tgt = _targets()
    src = np.broadcast_to(SONAR, tgt.shape)

    hf = (lambda x, y: s.height(x, y, time_s), np.eye(4)) if exact else None

    def go():
        return specular_points(m.vertices, m.faces, n, src, tgt, newton_iterations=newton,
                               height_field=hf)

    sp = go()
    return sp, best_time(go, repeat=3), len(m.faces)


def _compare(sp, ref):
    """Match each reference path to the nearest found one of the same pair: delay error (ns,
    two-way at 1500 m/s), level error (dB), and paths missed or extra."""
    d_ns, d_db, missed = [], [], 0
    for j in range(len(ref)):
        same = np.flatnonzero(sp.pair == ref.pair[j])
        if same.size == 0:
            missed += 1
            continue
        k = same[np.argmin(np.linalg.norm(sp.point_m[same] - ref.point_m[j], axis=1))]
        if np.linalg.norm(sp.point_m[k] - ref.point_m[j]) > 0.2:
            missed += 1
            continue
        L = sp.source_range_m[k] + sp.receiver_range_m[k]
        Lr = ref.source_range_m[j] + ref.receiver_range_m[j]
        d_ns.append(abs(L - Lr) / 1500 * 1e9)
        d_db.append(abs(20 * np.log10(abs(sp.divergence[k]) / abs(ref.divergence[j]))))
    extra = max(0, len(sp) - (len(ref) - missed))
    return (np.max(d_ns) if d_ns else np.nan, np.max(d_db) if d_db else np.nan, missed, extra)


def register(knob):
    @knob
    def sea_mesh_resolution():
        """Wavy-sea mesh resolution 1.0 … 0.1 m vs 0.05 m (bounce points and levels)."""
        ref, t_ref, f_ref = _paths(0.05, newton=20, exact=True)
        rows = []
        for res in (1.0, 0.5, 0.25, 0.1, 0.05):
            for exact in (True, False):
                sp, t, faces = _paths(res, exact=exact)
                dt, dl, miss, extra = _compare(sp, ref)
                rows.append([f"{res}" + (" (default)" if res == 0.25 else ""),
                             "exact surface (default)" if exact else "mesh", f"{faces:,}", len(sp),
                             f"{dt:.3g}", f"{dl:.3g}", miss, extra, f"{t * 1e3:.0f}"])
        return ("## Wavy-sea mesh resolution (`boundaries[].mesh.resolution_m` of `swell` / `wind_sea`)\n\n"
                "A swell of three waves (0.25 m × 12 m, 0.12 m × 7 m, 0.06 m × 4.5 m) over a "
                "32 × 14 m patch; the sonar 4 m down, 40 targets 1–6 m down and 8–24 m away; the "
                "transmit leg's one-bounce paths (specular points, acoustics/paths/specular.py) "
                "found on each mesh, refined either on the exact surface "
                "(`effects.specular.exact_surface: true`, the default for sea surfaces: the mesh "
                "only finds the points and decides visibility) or on the mesh alone (Phong-smooth "
                "facets from exact vertex normals: sag and curvature from interpolated normals), "
                "vs the exact refinement on a 0.05-m mesh. Errors: worst "
                "two-way delay of a matched path (ns, 1 ns ≈ 0.75 mm of range) and worst level "
                "(dB); paths missed or extra (a glint near the search's tolerance at a coarse "
                "mesh). Time: the search for 40 pairs.\n\n"
                + table(["resolution (m)", "refined on", "facets", "paths", "delay error (ns)",
                         "level error (dB)", "missed", "extra", "time (ms)"], rows)
                + "\n\nA wind sea's resolution also sets which waves exist at all (its spectrum "
                  "stops at the grid's Nyquist, π/Δ; the share left out is reported as "
                  "`unresolved_variance_fraction`), so at 420 kHz what the mesh cannot hold "
                  "belongs to the surface's diffuse scattering law.")

    @knob
    def specular_refinement():
        """Newton steps 0/1/2/4 on the smooth surface vs 20 (bounce points)."""
        ref, t_ref, faces = _paths(0.25, newton=20)
        rows = []
        for it in (0, 1, 2, 4, 8):
            sp, t, _ = _paths(0.25, newton=it)
            dt, dl, miss, extra = _compare(sp, ref)
            rows.append([f"{it}" + (" (default)" if it == 8 else ""), len(sp), f"{dt:.3g}",
                         f"{dl:.3g}", miss, extra, f"{t * 1e3:.0f}"])
        rows.append(["20 (reference)", len(ref), "0", "0", 0, 0, f"{t_ref * 1e3:.0f}"])
        return ("## Bounce-point refinement (`effects.specular.newton_iterations`)\n\n"
                f"As above on the 0.25-m mesh ({faces:,} facets), refined on the mesh alone "
                "(`exact_surface: false`; on the exact surface 8 steps converge alike): each "
                "bounce point starts from "
                "the zero of the linearly interpolated reflection-law residual on its facet and "
                "takes Newton steps on the smooth (Phong) surface, with the Hessian that also "
                "gives its level. 0 steps keeps the linear estimate (the level's curvature still "
                "comes from the facet). Errors as above.\n\n"
                + table(["Newton steps", "paths", "delay error (ns)", "level error (dB)", "missed",
                         "extra", "time (ms)"], rows)
                + "\n\nBounces: `effects.max_bounces` (the section above) counts planar and "
                  "curved bounces alike; a leg meets a curved boundary at most once, alone or "
                  "between planar bounces (Tx→surface→floor→target).")

    @knob
    def specular_cost():
        """The search and the per-ping rebuild on meshes of 10⁴–10⁶ facets."""
        from acoustics.paths.meshes import SceneMesh, _grid_mesh
        from acoustics.paths.raycast import RayCaster
        from acoustics.paths.sea_surface import wind_sea
        from acoustics.paths.specular import specular_points
        rows = []
        for size, res in ((20.0, 0.25), (56.0, 0.25), (100.0, 0.2), (160.0, 0.2)):
            s = wind_sea(wind_speed_m_s=10.0, fetch_m=20e3, size_m=(size, size), resolution_m=res,
                         seed=1, center_m=(size / 2 - 4, 0.0))
            t_grid = best_time(lambda: s.grid(1.0), repeat=3)
            v, n = s.grid(1.0)
            m = _grid_mesh(s.x_m, s.y_m, v[:, 2].reshape(s.y_m.size, s.x_m.size))
            t_cast = best_time(lambda: RayCaster([SceneMesh("sea", "boundary", "surface", m, None,
                                                            "sea")]), repeat=3)
            cells = []
            for n_t in (10, 100):
                tgt = _targets(n_t)
                src = np.broadcast_to(SONAR, tgt.shape)
                # transmit and receive legs: two pairs per target
                both_s = np.concatenate([src, src])
                both_p = np.concatenate([tgt, tgt])
                specular_points(m.vertices, m.faces, n, both_s[:2], both_p[:2])   # compile
                t0 = time.perf_counter()
                sp = specular_points(m.vertices, m.faces, n, both_s, both_p)
                cells.append((time.perf_counter() - t0, len(sp)))
            rows.append([f"{size:.0f} × {size:.0f} m at {res} m", f"{len(m.faces):,}",
                         f"{t_grid * 1e3:.0f}", f"{t_cast * 1e3:.0f}",
                         f"{cells[0][0] * 1e3:.0f} ({cells[0][1]} paths)",
                         f"{cells[1][0] * 1e3:.0f} ({cells[1][1]} paths)"])
        return ("## Cost of a moving sea per ping\n\n"
                "A JONSWAP sea (U₁₀ = 10 m/s, fetch 20 km) on growing grids: the new surface "
                "(inverse FFTs for heights and slopes), the Embree scene rebuilt on it, and the "
                "specular search for transmit and receive legs of 10 and 100 targets (compiled "
                "loop, one thread; blocks of 32 neighbouring facets whose normal cone cannot meet "
                "a pair's bisector are skipped — a bound, tested to find exactly what testing "
                "every facet finds — and the candidates refined as in a run). Times per ping "
                "(ms).\n\n"
                + table(["sea", "facets", "surface (ms)", "Embree rebuild (ms)",
                         "search, 10 targets", "search, 100 targets"], rows)
                + "\n\nThe search is O(pairs × blocks) plus the facets of the blocks that "
                  "pass (5–10 % on a wind sea): 10⁵ facets cost ≈ 1 ms per pair with 100 "
                  "targets (the block bounds are built once per call). A scene that does not "
                  "move its sea pays none of the surface or rebuild columns.")
