"""What simulating a scene will cost, estimated from the scene alone.

Upper bounds, computed before anything is allocated, so that ``abacus scene check`` can say "ok"
only for a scene that will run, and every command refuses up front — naming the key to change —
instead of dying half-way with an allocation error. The terms, in bytes:

``samples``       pings x channels x samples x 8 (complex64, held once for the dataset);
``synthesis``     per ping: the fine grid (``effects.oversampling``) of every channel, its FFT
                  and the convolution: 4 x channels x U (samples + pulse) x 16;
``scatterers``    per ping: targets (a population by density: its Poisson mean + 6 σ), boundary
                  facets (reverberation rays) and mesh-target facets, ≈ 200 bytes each, and with
                  Huygens directivity one complex number per scatterer and element;
``meshes``        faces x 100 (vertices, faces, normals, Embree's copy);
``writing``       the samples again (the NetCDF writer copies each variable once);
``runtime``       thread pools, FFT plans, xarray objects: 100 MB.

The processing chain's terms come from :func:`processing.chain.chain_memory_terms`, the
figures' from the application; callers pass them as ``extra_terms``.
"""
from __future__ import annotations

import math

from processing.base.resources import Estimate

__all__ = ["estimate_scene", "mesh_faces", "population_bound", "reverberation_rays"]

_SCATTERER_BYTES = 200.0
_FACE_BYTES = 100.0


def population_bound(pop) -> int:
    """Most targets a population puts in a ping: its count, or mean + 6 σ of its Poisson draw."""
    if getattr(pop, "count", None) is not None:
        return int(pop.count)
    mean = float(pop.density_per_m3) * float(pop.volume_m3)
    return int(math.ceil(mean + 6.0 * math.sqrt(mean) + 1))


def mesh_faces(spec) -> int:
    """Triangles a mesh spec builds (files: the size of the file as a bound, 50 bytes a face)."""
    shape = spec.mesh
    kind = getattr(shape, "shape", "")
    if kind == "plane":
        return 2 * int(shape.segments[0]) * int(shape.segments[1])
    if kind in ("rough_floor", "wind_sea", "swell"):
        nx = math.ceil(shape.size_m[0] / shape.resolution_m) + 1
        ny = math.ceil(shape.size_m[1] / shape.resolution_m) + 1
        return 2 * nx * ny
    if kind in ("sphere", "spheroid"):
        return 20 * 4 ** int(shape.subdivisions)
    if kind == "box":
        return 12
    return 0  # files: bounded by their size when read (paths/meshes.py)


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
    n_targets = len(scene.targets.points) + sum(population_bound(p) for p in scene.targets.populations)
    rays = reverberation_rays(scene, sonar)
    faces = sum(mesh_faces(s) for s in (*scene.boundaries, *scene.targets.meshes))
    mesh_target_faces = sum(mesh_faces(s) for s in scene.targets.meshes)
    n_scat = n_targets * (1 + 2 * fx.multipath_order * max(1, len(scene.boundaries))) + rays + mesh_target_faces
    scatterers = n_scat * _SCATTERER_BYTES
    if fx.directivity == "huygens":
        scatterers += float(n_scat) * n_ch * 16
    meshes = faces * _FACE_BYTES + rays * 64.0
    terms = [("samples", samples), ("synthesis per ping", synthesis), ("scatterers per ping", scatterers),
             ("meshes and rays", meshes), ("runtime", _RUNTIME_BYTES)]
    terms += list(extra_terms)
    stored = sum(b for name, b in extra_terms if name == "stored images")
    if write:
        terms.append(("writing", samples))
    memory = sum(b for _, b in terms)
    output = (samples + stored + n_p * n_targets * 200.0) if write else 0.0
    return Estimate(memory, output, terms,
                    keys=("pings.count (or --pings), sampling.samples, the targets' count or "
                          "density, effects.reverberation.rays_per_square_degree, mesh segments"))
