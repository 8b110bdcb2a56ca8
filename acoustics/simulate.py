"""``acoustics.simulate``: a scene becomes a SONAR-netCDF4-flavoured dataset of per-element echoes.

Per ping p (independent of every other ping; all draws seeded by (seed, p, stream)):

1. ``targets``        draw the point targets (positions, backscatter, phases);
2. ``occlusion``      drop the direct echo of targets a mesh shadows   — only with meshes;
3. ``multipath``      specular image-source paths                       — only if multipath_order > 0;
4. ``mesh_targets``   physical-optics facets of mesh targets            — only with mesh targets;
5. ``reverberation``  boundary facet scatterers from transmit rays      — only if enabled;
6. ``echoes``         synthesise every receiver element's complex baseband samples (fast or exact);
7. ``noise``          add band-limited receiver noise                   — only if ``noise.enabled``;
8. ``adc``            quantise and clip to the ADC's range              — only if ``quantize``.

``setup`` (arrays, pulse, transmit beamwidths, and the Embree scene when there are meshes) runs
once per call and ``dataset`` assembles the output; the provenance records the stages that ran,
their wall time and the rays cast per purpose. Stages a scene does not need are not entered (a
scene without meshes never builds a ray caster, a quiet one has no ``noise`` stage).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .beams import beamwidth
from .echoes import EchoModel
from .medium import Medium
from .receiver_chain import band_limited_noise, quantize
from .signal import Pulse
from .sonar import Sonar, build_sonar
from .stages import StageLog
from .synthesis import synthesize
from .targets import TargetSet, draw_targets, ping_rng

__all__ = ["Setup", "make_setup", "simulate_ping", "simulate", "counting_volume_of"]


@dataclass(frozen=True, eq=False)
class Setup:
    """Everything fixed for a run of one scene."""

    sonar: Sonar
    medium: Medium
    pulse: Pulse
    model: EchoModel
    tx_beamwidth_az_rad: float
    tx_beamwidth_el_rad: float
    counting_range_m: tuple
    ray_scene: object = None


_ARRAY_CACHE: dict = {}


def _per_geometry(name, key, compute):
    """Results that depend only on array geometry and the medium, computed once per process
    (keyed by the geometry's bytes: arrays rebuilt from the same scene hit the cache)."""
    k = (name, key)
    if k not in _ARRAY_CACHE:
        if len(_ARRAY_CACHE) > 64:
            _ARRAY_CACHE.clear()
        _ARRAY_CACHE[k] = compute()
    return _ARRAY_CACHE[k]


def _tx_beamwidths(key, tx, c, f0):
    def compute():
        m = Medium(sound_speed_m_s=c)
        return (beamwidth(tx, plane="azimuth", medium=m, frequency_hz=f0),
                beamwidth(tx, plane="elevation", medium=m, frequency_hz=f0))
    return _per_geometry("tx_beamwidths", (key, c, f0), compute)


def calibration_of(setup: "Setup"):
    """(G (counts m), azimuth grid (rad), Φ(θ) (rad)) of a run: see :mod:`acoustics.calibration`."""
    from .calibration import calibration_gain_counts, two_way_elevation_width
    tx = setup.sonar.transmitter
    rx = setup.sonar.receiver.elements
    k = setup.model.wavenumber_rad_m
    key = (_array_key(tx), _array_key(rx), k)
    az, width = _per_geometry("elevation_width", key, lambda: two_way_elevation_width(
        tx, rx, wavenumber_rad_m=k))
    return calibration_gain_counts(tx, setup.model.scale_counts), az, width


def _array_key(arr) -> bytes:
    return b"".join(np.ascontiguousarray(a).tobytes() for a in
                    (arr.center_m, arr.width_m, arr.height_m, arr.rotation_rad, arr.weight))


def make_setup(scene, log: StageLog | None = None) -> Setup:
    """Build the arrays, medium, pulse and echo model of a scene (once per run), and its ray
    scene when it has meshes."""
    sonar = build_sonar(scene)
    medium = Medium.from_spec(scene.medium)
    pulse = Pulse.from_spec(scene.signal)
    fx = scene.effects
    model = EchoModel(sonar.transmitter, sonar.receiver.elements, medium,
                      scene.signal.center_frequency_hz, scene.sampling.adc.scale_counts,
                      fx.directivity, tuple(fx.huygens_subdivisions), fx.baffle, fx.spreading,
                      fx.absorption)
    tx = sonar.transmitter
    az, el = _tx_beamwidths(_array_key(tx), tx, medium.sound_speed_m_s,
                            scene.signal.center_frequency_hz)
    rng_m = scene.processing.image.range_m
    if rng_m is None:
        c, s = medium.sound_speed_m_s, scene.sampling
        rng_m = (c * s.time_offset_s / 2, c * (s.time_offset_s + s.samples / s.rate_hz) / 2)
    setup = Setup(sonar, medium, pulse, model, az, el, tuple(float(r) for r in rng_m))
    if scene.boundaries or scene.targets.meshes:
        from .raytraced import build_ray_scene
        log = log if log is not None else StageLog()
        with log.stage("rays_build"):
            object.__setattr__(setup, "ray_scene", build_ray_scene(scene, setup))
    return setup


def counting_volume_of(setup: Setup, positions_sonar_m) -> np.ndarray:
    """True where a sonar-frame position lies in the default counting volume: the
    transmitter's 3 dB beam in azimuth and elevation and the image's range limits."""
    p = np.asarray(positions_sonar_m, float).reshape(-1, 3)
    r = np.linalg.norm(p, axis=1)
    az = np.arctan2(p[:, 0], p[:, 2])
    el = np.arctan2(p[:, 1], np.hypot(p[:, 0], p[:, 2]))
    r0, r1 = setup.counting_range_m
    return ((r >= r0) & (r <= r1) & (np.abs(az) <= setup.tx_beamwidth_az_rad / 2)
            & (np.abs(el) <= setup.tx_beamwidth_el_rad / 2))


def _with_shadow(targets: TargetSet, shadowed):
    """The target set with its shadowing recorded (ground truth)."""
    from dataclasses import replace
    return replace(targets, shadowed=np.asarray(shadowed, bool))


def simulate_ping(scene, setup: Setup, ping: int, *, seed: int | None = None,
                  log: StageLog | None = None):
    """One ping.

    Returns
    -------
    samples : ndarray, shape (n_channels, n_samples), complex128
        ADC counts.
    clipped : ndarray of int, shape (n_channels,), or None
        Clipped samples per channel (None when the ADC does not quantise).
    targets : TargetSet
    """
    seed = scene.seed if seed is None else int(seed)
    log = log if log is not None else StageLog()
    s, fx = scene.sampling, scene.effects
    n_ch = setup.sonar.n_channels
    with log.stage("targets"):
        targets = draw_targets(scene, ping, setup.sonar.pose, seed=seed)
    strength = targets.rho_m * np.exp(1j * targets.phase_rad)
    rs = setup.ray_scene
    shadowed = np.zeros(len(targets), bool)
    if rs is not None and fx.occlusion and len(targets):
        with log.stage("occlusion"):
            shadowed = rs.shadowed(targets.position_sonar_m)
    from .raytraced import VirtualScatterers
    direct = ~shadowed
    parts = [VirtualScatterers(targets.position_sonar_m[direct], targets.position_sonar_m[direct],
                               strength[direct], np.full(int(direct.sum()), "direct"))]
    if rs is not None and fx.multipath_order > 0 and rs.planes and len(targets):
        with log.stage("multipath"):
            parts.append(rs.multipath(targets.position_sonar_m, strength, fx.multipath_order))
    if rs is not None and scene.targets.meshes:
        with log.stage("mesh_targets"):
            parts.append(rs.mesh_targets())
    if rs is not None and fx.reverberation.enabled and scene.boundaries:
        with log.stage("reverberation"):
            parts.append(rs.reverberation(scene, setup, ping, seed))
    vs = VirtualScatterers.concat(parts)
    if len(vs):
        with log.stage("echoes"):
            bistatic = not np.array_equal(vs.p_tx, vs.p_rx)
            x = synthesize(setup.model, vs.p_tx, vs.strength, pulse=setup.pulse,
                           rate_hz=s.rate_hz, n_samples=s.samples, t0_s=s.time_offset_s,
                           method=fx.synthesis, kernel_length=fx.kernel_length,
                           oversampling=fx.oversampling,
                           receive_positions_m=vs.p_rx if bistatic else None)
    else:
        x = np.zeros((n_ch, s.samples), complex)
    targets = _with_shadow(targets, shadowed)
    if scene.noise.enabled and scene.noise.sigma_counts > 0:
        with log.stage("noise"):
            x = x + band_limited_noise(ping_rng(seed, ping, "noise"), n_ch, s.samples,
                                       sigma_counts=scene.noise.sigma_counts,
                                       bandwidth_hz=scene.noise.bandwidth_hz, rate_hz=s.rate_hz)
    clipped = None
    if s.adc.quantize:
        with log.stage("adc"):
            x, clipped = quantize(x, s.adc.bits)
    return x, clipped, targets


def simulate(scene, *, pings=None, seed: int | None = None, progress=None):
    """Simulate a scene.

    Parameters
    ----------
    scene : Scene
        From :func:`acoustics.load_scene`.
    pings : iterable of int, optional
        Ping indices; default ``scene.pings`` (first .. first + count − 1). Each ping depends
        only on (seed, ping index), so any subset or order gives the same pings.
    seed : int, optional
        Overrides ``scene.seed``.
    progress : callable(done, total), optional
        Called after each ping.

    Returns
    -------
    xarray.DataTree
        The data contract of DESIGN.md (processing.dataset): per-element samples as float32
        ``element_r``/``element_i`` (ping_time, rx_element, range_sample), geometry, pulse and
        replica, environment, ground truth, provenance with the resolved scene and stage times.
    """
    import xarray as xr

    from .simulated_dataset import build_tree, provenance_dataset
    seed = scene.seed if seed is None else int(seed)
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if pings is None:
        pings = range(scene.pings.first, scene.pings.first + scene.pings.count)
    pings = [int(p) for p in pings]
    if any(p < 0 for p in pings):
        raise ValueError("ping indices must be >= 0")
    log = StageLog()
    with log.stage("setup"):
        setup = make_setup(scene, log)
    n_ch, n = setup.sonar.n_channels, scene.sampling.samples
    samples = np.zeros((len(pings), n_ch, n), np.complex64)
    clipped = np.zeros((len(pings), n_ch), int) if scene.sampling.adc.quantize else None
    truth: list[TargetSet] = []
    for i, p in enumerate(pings):
        x, c, t = simulate_ping(scene, setup, p, seed=seed, log=log)
        samples[i] = x
        if clipped is not None:
            clipped[i] = c
        truth.append(t)
        if progress is not None:
            progress(i + 1, len(pings))
    with log.stage("dataset"):
        tree = build_tree(scene, setup, pings, samples, clipped, truth, log, seed)
    # the provenance was written inside the "dataset" stage: rewrite it with that stage's time
    from .simulated_dataset import _rays
    tree["Provenance"] = xr.DataTree(provenance_dataset(scene, seed, log, _rays(setup)))
    return tree
