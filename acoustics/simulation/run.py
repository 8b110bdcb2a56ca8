"""``acoustics.simulate``: a scene becomes a SONAR-netCDF4-flavoured dataset of per-element echoes.

Per ping p (independent of every other ping; all draws seeded by (seed, p, stream)):

1. ``targets``        draw the point targets (positions, backscatter, phases);
2. ``occlusion``      drop the direct echo of targets a mesh shadows   — only with meshes;
3. ``multipath``      specular image-source paths                       — only if max_bounces > 0;
4. ``mesh_targets``   physical-optics facets of mesh targets            — only with mesh targets;
5. ``reverberation``  boundary facet scatterers from transmit rays      — only if enabled;
6. ``echoes``         synthesise every receiver element's complex baseband samples (fast or exact);
7. ``noise``          add band-limited receiver noise                   — only if ``noise.enabled``;
8. ``adc``            quantise and clip to the ADC's range              — only if ``quantize``.

``setup`` resolves the scene once per call into a frozen :class:`~acoustics.simulation.setup.Setup`
(arrays, pulse, transmit beamwidths, what each stage reads, the meshes when there are any) and
builds the run's :class:`~acoustics.simulation.setup.RunCache` (the Embree scene); the ping loop
reads the setup only (no Scene below this module) and ``dataset`` assembles the output; the provenance records the stages that ran,
their wall time and the rays cast per purpose. Stages a scene does not need are not entered (a
scene without meshes never builds a ray caster, a quiet one has no ``noise`` stage).
"""
from __future__ import annotations

import numbers
import os

import numpy as np
import xarray as xr

from processing.base.contract import PROVENANCE_GROUP

from acoustics.simulation.dataset import build_tree, provenance_dataset, rays_cast
from acoustics.simulation.ping import simulate_ping
from acoustics.simulation.setup import RunCache, make_setup
from acoustics.simulation.stages import StageLog
from acoustics.targets.draw import TargetSet

__all__ = ["simulate"]


def simulate(scene, *, pings=None, seed: int | None = None, progress=None,
             arrivals: bool | None = None):
    """Simulate a scene.

    Parameters
    ----------
    scene : Scene, str or Path
        From :func:`acoustics.load_scene`, or what it takes: a scene file's path or a built-in
        scene's name (``"two_targets"``).
    pings : int or iterable of int, optional
        Ping indices; default ``scene.pings`` (first .. first + count − 1). An int ``n``: the
        scene's first ``n`` pings (first .. first + n − 1, as ``abacus run --pings n``), i.e.
        ``range(n)`` for a scene that starts at ping 0. Each ping depends only on (seed, ping
        index), so any subset or order gives the same pings.
    seed : int, optional
        Overrides ``scene.seed``.
    progress : callable(done, total), optional
        Called after each ping.
    arrivals : bool, optional
        Record every arrival of every ping (overrides ``effects.arrivals.enabled``): the
        group /Vendor_specific/Arrivals, one row per path (docs/dataset.md, "Arrivals"), which
        ``tree["Vendor_specific/Arrivals"].to_dataset()`` gives as a table.

    Returns
    -------
    xarray.DataTree
        The data contract of DESIGN.md (processing.base.dataset): per-element samples as float32
        ``backscatter_r``/``backscatter_i`` (channel, ping_time, range_sample, beam) in /Sonar/Beam_group1, geometry, pulse and
        replica, environment, ground truth, provenance with the resolved scene and stage times.

    Examples
    --------
    >>> scene = acoustics.load_scene("default")            # a built-in scene, or a path
    >>> tree = acoustics.simulate(scene, pings=range(2), seed=7)
    >>> tree["Sonar/Beam_group1"]["backscatter_r"].dims
    ('channel', 'ping_time', 'range_sample', 'beam')
    >>> tree = acoustics.simulate("scenes/two_targets.yaml", pings=2)   # a path, 2 pings
    """
    if isinstance(scene, (str, os.PathLike)):
        from acoustics.scene.load import load_scene
        scene = load_scene(scene)
    seed = scene.seed if seed is None else int(seed)
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if pings is None:
        pings = range(scene.pings.first, scene.pings.first + scene.pings.count)
    elif isinstance(pings, numbers.Integral) and not isinstance(pings, bool):
        if pings < 1:
            raise ValueError(f"pings must be >= 1 (a number of pings) or ping indices, got {pings}")
        pings = range(scene.pings.first, scene.pings.first + int(pings))
    pings = [int(p) for p in pings]
    if any(p < 0 for p in pings):
        raise ValueError("ping indices must be >= 0")
    if arrivals is not None and bool(arrivals) != scene.effects.arrivals.enabled:
        fx = scene.effects
        scene = scene.model_copy(update={"effects": fx.model_copy(update={
            "arrivals": fx.arrivals.model_copy(update={"enabled": bool(arrivals)})})})
    log = StageLog()
    with log.stage("setup"):
        setup = make_setup(scene, log)
        cache = RunCache(setup, log)
    n_ch, n = setup.sonar.n_channels, setup.sampling.samples
    # I and Q as the dataset stores them: float32 (ping, range_sample, beam), so the dataset wraps
    # them and the writer writes them without a copy
    samples = (np.zeros((len(pings), n, n_ch), np.float32), np.zeros((len(pings), n, n_ch), np.float32))
    clipped = np.zeros((len(pings), n_ch), int) if setup.sampling.quantize else None
    truth: list[TargetSet] = []
    tables = [] if setup.effects.arrivals else None
    for i, p in enumerate(pings):
        x, c, t = simulate_ping(setup, p, cache=cache, seed=seed, log=log, arrivals=tables)
        samples[0][i] = x.real.T
        samples[1][i] = x.imag.T
        if clipped is not None:
            clipped[i] = c
        truth.append(t)
        if progress is not None:
            progress(i + 1, len(pings))
    with log.stage("dataset"):
        tree = build_tree(scene, setup, pings, samples, clipped, truth, log, seed,
                          arrivals=tables, rays=rays_cast(cache))
    # the provenance was written inside the "dataset" stage: rewrite it with that stage's time
    tree[PROVENANCE_GROUP] = xr.DataTree(provenance_dataset(scene, seed, log, rays_cast(cache)))
    return tree
