"""What simulating a scene will cost, estimated from the scene alone.

Upper bounds, computed before anything is allocated, so that ``abacus scene check`` can say "ok"
only for a scene that will run, and every command refuses up front — naming the key to change —
instead of dying half-way with an allocation error. The terms, in bytes:

``samples``       pings x channels x samples x 8 (complex64, held once for the dataset);
``synthesis``     per ping: the fine grid (``effects.oversampling``) of every channel, its FFT
                  and the convolution: 4 x channels x U (samples + pulse) x 16 (the work
                  buffers the synthesis keeps from ping to ping, acoustics/synthesis/arrivals.py
                  ``_scratch``, are part of this and the next term, which the estimate holds for
                  the whole run);
``scatterers``    per ping: targets (a population by density: its Poisson mean + 6 σ), boundary
                  facets (reverberation rays) and mesh-target facets, ≈ 200 bytes each, and with
                  Huygens directivity one complex number per scatterer and element;
``schools``       drawing a school (random sequential adsorption): its candidates, k-d trees and
                  the kept draws (up to 17), ≈ 800 bytes a fish;
``meshes``        faces x 1300 (vertices, faces, normals, the caster's planes, Embree's copy and
                  BVH, the specular search's vertex normals, blocks and their tree: the hard
                  survey's peak grows 0.9–1.2 kB a floor facet from 10⁶ to 3·10⁶ as the search
                  changes, docs/performance.md, "scaling"); the faces of a file
                  come from its header before it is read (STL, PLY, OFF, .npy grids), else from
                  its size (:func:`acoustics.paths.meshes.mesh_file_faces`); procedural shapes
                  from their keys (a plane's ``segments``, a grid's ``size_m / resolution_m``);
``floor tiles``   a ``rough_floor`` streamed in tiles (``effects.floor_tiles.enabled``):
                  the tiles held at once, at most the setting (or the whole floor's tiles if
                  fewer), and building one more: its vertices with a halo, the noise the
                  kernel reads (:func:`tiled_floor_bytes`), instead of its faces x 100;
``mesh files``    reading them: the bytes and what the reader makes of them (3 x a binary
                  file, 11 x a text file);
``motion``        a motion series: its rows (a file's: at most its size / 4, or the row cap)
                  x 5 columns x 8 bytes, held a few times over (parsing, interpolation), and a
                  motion file's text (3 x its size);
``writing``       the samples again (the NetCDF writer copies each variable once);
``runtime``       thread pools, FFT plans, xarray objects: 100 MB.

The processing chain's terms come from :func:`processing.chain.chain_memory_terms`, the
figures' from the application; callers pass them as ``extra_terms``.
"""
from __future__ import annotations

import math

from processing.base.resources import Driver, Estimate

__all__ = ["estimate_scene", "mesh_faces", "tiled_floor_bytes", "mesh_face_key", "population_bound", "reverberation_rays",
           "motion_rows"]

_SCATTERER_BYTES = 200.0
_FACE_BYTES = 1300.0
_SCHOOL_FISH_BYTES = 800.0
_MOTION_ROW_BYTES = 5 * 8 * 6.0
#: what no estimate exceeds (a count of 1e300 is "too many", not an OverflowError)
_HUGE = 1e30


def _finite(x: float) -> float:
    x = float(x)
    return x if math.isfinite(x) and x < _HUGE else _HUGE


def population_bound(pop) -> int:
    """Most targets a population puts in a ping: its count, or mean + 6 σ of its Poisson draw
    (schools too: a school by density draws a Poisson number of fish in its ellipsoid)."""
    if getattr(pop, "count", None) is not None:
        return int(pop.count)
    mean = _finite(float(pop.density_per_m3) * _finite(pop.volume_m3))
    return int(_finite(math.ceil(mean + 6.0 * math.sqrt(mean) + 1)))


def mesh_faces(spec, resolve=None) -> float:
    """Triangles a mesh spec builds, an upper bound known before it is built.

    Parameters
    ----------
    spec : BoundarySpec or MeshTargetSpec
    resolve : callable(str) -> Path, optional
        The scene's :meth:`~acoustics.scene.schema.Scene.resolve_path`: files (mesh files,
        height grids) are then bounded from their headers or sizes
        (:func:`acoustics.paths.meshes.mesh_file_faces`), without being read; without it they
        count 0.
    """
    shape = spec.mesh
    kind = getattr(shape, "shape", "")
    if kind == "plane":
        return _finite(2.0 * int(shape.segments[0]) * int(shape.segments[1]))
    if kind in ("rough_floor", "wind_sea", "swell"):
        nx = _finite(shape.size_m[0] / shape.resolution_m)
        ny = _finite(shape.size_m[1] / shape.resolution_m)
        return _finite(2.0 * (math.ceil(nx) + 1) * (math.ceil(ny) + 1)) if nx < _HUGE and ny < _HUGE else _HUGE
    if kind in ("sphere", "spheroid"):
        return float(20 * 4 ** int(shape.subdivisions))
    if kind == "box":
        return 12.0
    file = getattr(shape, "file", None)
    if file is None or resolve is None:
        return 0.0
    from acoustics.paths.meshes import mesh_file_faces
    return _finite(mesh_file_faces(resolve(file)))


def tiled_floor_bytes(scene, spec) -> float | None:
    """Memory (bytes) of a boundary streamed in tiles (acoustics/paths/tiles.py): the built
    tiles, at most ``effects.floor_tiles.memory_mb``, and the temporaries of building one;
    None for a mesh built whole (not a ``rough_floor``, or the setting unset)."""
    tiles = scene.effects.floor_tiles
    shape = spec.mesh
    if not tiles.enabled or getattr(shape, "shape", "") != "rough_floor":
        return None
    from acoustics.paths.tiles import tile_bytes
    t = int(tiles.tile_vertices)
    whole = mesh_faces(spec) * tile_bytes(t) / (2.0 * (t - 1) ** 2)
    half = math.ceil(4.0 * shape.correlation_length_m / shape.resolution_m) if shape.rms_height_m > 0 else 0
    build = (t + 2) ** 2 * 3 * 8 * 4 + (t + 2 * half) ** 2 * 8 * 3
    return _finite(min(float(tiles.memory_mb) * 1e6, whole) + build)


def mesh_face_key(spec) -> str:
    """The key of a mesh spec that sets its number of faces (relative to its ``mesh``)."""
    kind = getattr(spec.mesh, "shape", "")
    return {"plane": "segments", "rough_floor": "resolution_m", "wind_sea": "resolution_m",
            "swell": "resolution_m", "sphere": "subdivisions", "spheroid": "subdivisions",
            "box": "size_m"}.get(kind, "file")


def _file_bytes(spec, resolve) -> float:
    """Memory of reading a mesh or grid file (:func:`acoustics.paths.meshes.mesh_file_read_bytes`)."""
    file = getattr(spec.mesh, "file", None)
    if file is None or resolve is None:
        return 0.0
    from acoustics.paths.meshes import mesh_file_read_bytes
    return _finite(mesh_file_read_bytes(resolve(file)))


def motion_rows(scene) -> tuple[float, float]:
    """(rows, bytes of the file) of a scene's motion series, known before a file is read: an
    inline series' times; a file's rows at most one per 4 bytes ("0,0" and its line end) and
    at most :data:`~acoustics.sonar.platform.MAX_MOTION_ROWS`."""
    motion = scene.sonar.motion
    if motion is None or motion.kind == "swell":
        return 0.0, 0.0
    if motion.kind == "series":
        return float(len(motion.series.time_s)), 0.0
    import os

    from acoustics.sonar.platform import MAX_MOTION_ROWS
    try:
        size = float(os.stat(scene.resolve_path(motion.file)).st_size)
    except (OSError, ValueError):
        return 0.0, 0.0
    return min(float(MAX_MOTION_ROWS), size / 4.0), size


def reverberation_rays(scene, sonar) -> int:
    """Rays of the reverberation fan (cast once per run)."""
    spec = scene.effects.reverberation
    if not (spec.enabled and scene.boundaries):
        return 0
    from acoustics.medium import Medium
    from acoustics.sonar.beams import illuminated_extent
    kw = dict(medium=Medium.from_spec(scene.medium), frequency_hz=scene.signal.center_frequency_hz)
    tx = sonar.transmitter
    az = illuminated_extent(tx, plane="azimuth", level_db=spec.beam_level_db, **kw)
    el = illuminated_extent(tx, plane="elevation", level_db=spec.beam_level_db, **kw)
    root = math.sqrt(spec.rays_per_square_degree)
    n_az = max(2, math.ceil(math.degrees(az[1] - az[0]) * root))
    n_el = max(2, math.ceil(math.degrees(el[1] - el[0]) * root))
    return n_az * n_el


#: what any run holds besides its arrays: thread pools, FFT plans, xarray objects (measured ≈ 80 MB)
_RUNTIME_BYTES = 100e6


def estimate_scene(scene, *, pings: int | None = None, write: bool = True,
                   extra_terms=()) -> Estimate:
    """Memory and output of simulating a scene (and what the caller adds: the processing chain,
    stored images, figures).

    Parameters
    ----------
    scene : Scene
    pings : int, optional
        Default the scene's ``pings.count``.
    write : bool
        Include the dataset writer.
    extra_terms : sequence of (str, float)
        What the caller's own stages hold at once (bytes), e.g. processing's
        (:func:`processing.chain.chain_memory_terms`); a term named ``"stored images"`` counts
        towards the output too.

    Returns
    -------
    Estimate
    """
    from acoustics.scene.targets_spec import SchoolPopulation
    from acoustics.sonar.build import build_sonar
    sonar = build_sonar(scene)
    n_p = int(scene.pings.count if pings is None else pings)
    n_ch = int(sonar.n_channels)
    n_s = int(scene.sampling.samples)
    fx = scene.effects
    pulse = scene.signal.duration_s * scene.sampling.rate_hz
    up = fx.oversampling if fx.synthesis == "fast" else 1
    samples = float(n_p) * n_ch * n_s * 8
    synthesis = 4.0 * n_ch * up * (n_s + pulse) * 16
    resolve = scene.resolve_path
    per_pop = [float(population_bound(p)) for p in scene.targets.populations]
    n_targets = len(scene.targets.points) + sum(per_pop)
    rays = reverberation_rays(scene, sonar)
    mesh_specs = [(f"boundaries[{i}]", b) for i, b in enumerate(scene.boundaries)]
    mesh_specs += [(f"targets.meshes[{i}]", t) for i, t in enumerate(scene.targets.meshes)]
    per_mesh = [mesh_faces(spec, resolve) for _, spec in mesh_specs]
    tiled = [tiled_floor_bytes(scene, spec) for _, spec in mesh_specs]
    faces = sum(n for n, t in zip(per_mesh, tiled) if t is None)
    mesh_target_faces = sum(n for (key, _), n in zip(mesh_specs, per_mesh) if key.startswith("targets"))
    # legs per target: direct and every sequence of up to K bounces among B boundaries, no
    # boundary twice in a row (Σ B (B − 1)^(k−1)); a path is a pair of legs (an estimate:
    # glints of a wavy sea can add a few per sequence)
    n_b = max(1, len(scene.boundaries))
    legs = 1 + sum(n_b * (n_b - 1) ** (k - 1) for k in range(1, fx.max_bounces + 1))
    per_target = legs * legs
    scatterer_bytes = _SCATTERER_BYTES + (n_ch * 16.0 if fx.directivity == "huygens" else 0.0)
    n_scat = n_targets * per_target + rays + mesh_target_faces
    scatterers = n_scat * scatterer_bytes
    schools = sum(n for n, p in zip(per_pop, scene.targets.populations)
                  if isinstance(p, SchoolPopulation)) * _SCHOOL_FISH_BYTES
    meshes = faces * _FACE_BYTES + rays * 64.0
    floor_tiles = sum(t for t in tiled if t is not None)
    file_bytes = [_file_bytes(spec, resolve) for _, spec in mesh_specs]
    rows, motion_file = motion_rows(scene)
    motion = rows * _MOTION_ROW_BYTES + 3.0 * motion_file
    terms = [("samples", samples), ("synthesis per ping", synthesis), ("scatterers per ping", scatterers),
             ("meshes and rays", meshes), ("runtime", _RUNTIME_BYTES)]
    for name, b in (("schools", schools), ("floor tiles", floor_tiles), ("mesh files", sum(file_bytes)),
                    ("motion", motion)):
        if b > 0:
            terms.append((name, b))
    terms += list(extra_terms)
    stored = sum(b for name, b in extra_terms if name == "stored images")
    if write:
        terms.append(("writing", samples))
    memory = sum(b for _, b in terms)
    output = (samples + stored + n_p * n_targets * 200.0) if write else 0.0
    # the keys the memory grows with, and their shares (a refusal names the largest)
    chain = sum(b for name, b in extra_terms if name not in ("figures", "runtime"))
    per_run = samples * (2 if write else 1) + chain
    drivers = [Driver("pings.count (or --pings)", n_p, "pings", per_run),
               Driver("sampling.samples", n_s, "samples a ping", per_run + synthesis)]
    for j, (n, p) in enumerate(zip(per_pop, scene.targets.populations)):
        share = n * (per_target * scatterer_bytes + (_SCHOOL_FISH_BYTES if isinstance(p, SchoolPopulation) else 0.0))
        if p.count is not None:
            drivers.append(Driver(f"targets.populations[{j}].count", n, "targets", share))
        else:   # the draw grows with the density (its bound, mean + 6 σ, a little faster)
            drivers.append(Driver(f"targets.populations[{j}].density_per_m3", p.density_per_m3,
                                  "per m³", share))
    for (key, spec), n, fb, tb in zip(mesh_specs, per_mesh, file_bytes, tiled):
        if tb is not None:      # bounded by its setting, not by its faces
            drivers.append(Driver("effects.floor_tiles.memory_mb", scene.effects.floor_tiles.memory_mb,
                                  "MB", tb))
            continue
        share = n * (_FACE_BYTES + (scatterer_bytes if key.startswith("targets") else 0.0)) + fb
        drivers.append(Driver(f"{key}.mesh.{mesh_face_key(spec)}", n, "faces", share))
    if rays:
        drivers.append(Driver("effects.reverberation.rays_per_square_degree", rays, "rays",
                              rays * (64.0 + scatterer_bytes)))
    if rows:
        key = "sonar.motion.file" if scene.sonar.motion.kind == "file" else "sonar.motion.series"
        drivers.append(Driver(key, rows, "rows", motion))
    return Estimate(_finite(memory), _finite(output), terms,
                    keys=("pings.count (or --pings), sampling.samples, the targets' count or "
                          "density, effects.reverberation.rays_per_square_degree, mesh segments, "
                          "resolutions and files, effects.floor_tiles.memory_mb, the motion "
                          "file's rows"),
                    drivers=drivers)
