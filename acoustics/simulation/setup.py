"""The resolve step: a Scene becomes the frozen :class:`Setup` that the ping loop runs on.

Below :func:`acoustics.simulate`, :func:`make_setup` reads the Scene for the ping loop (the
writer, ``dataset.py``, reads it only to record it, and ``budget.py`` before the run). It
builds the arrays, medium, pulse and echo model, and resolves every section the ping loop needs
into small frozen values (:class:`Sampling`, :class:`Noise`, :class:`Effects`,
:class:`Reverberation`, the targets' :class:`~acoustics.targets.draw.Targets`, the boundary and
mesh-target meshes of :class:`Rays`, their file paths resolved against the scene file's folder).
Nothing below takes a Scene, and nothing mutates a Setup: what a run fills as it goes (the ray
caster, a tiled floor's built tiles, a moving sea's time, the rays cast, cached
reverberation rays) lives in the run's
:class:`RunCache`.

Geometry-only results (transmit beamwidths, the calibration) are cached per process by the
bytes of the geometry (:func:`acoustics.sonar.cache.per_geometry`), so scenes rebuilt from
the same file hit the cache.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from acoustics.frames import Pose
from acoustics.medium import Medium
from acoustics.simulation.stages import StageLog
from acoustics.sonar.beams import beamwidth
from acoustics.sonar.build import Sonar, build_sonar
from acoustics.sonar.cache import array_key, per_geometry
from acoustics.sonar.pulse import Pulse
from acoustics.synthesis.arrivals import EchoModel
from acoustics.targets.draw import TargetPoint, Targets
from processing.base.counting_volume import CountingVolume, counting_volume, image_range_of

if TYPE_CHECKING:       # meshes (trimesh, Embree) load only for a scene that has some
    from acoustics.paths.meshes import MeshSources

__all__ = ["Setup", "Sampling", "Noise", "Effects", "Reverberation", "Rays", "RunCache",
           "make_setup", "resolve_mesh_sources", "counting_volume_of"]


@dataclass(frozen=True)
class Sampling:
    """Complex baseband sampling and the ADC (thesis Table 3.4, §3.6)."""

    rate_hz: float
    """Sample rate (Hz)."""
    samples: int
    """Samples per ping."""
    time_offset_s: float
    """Time (s) of sample 0 after the start of transmission."""
    quantize: bool
    """Round to integers and clip to the signed range of ``bits``."""
    bits: int


@dataclass(frozen=True)
class Noise:
    """Band-limited receiver noise (thesis §2.4.2); ``sigma_counts`` 0: none added."""

    sigma_counts: float
    """Standard deviation (ADC counts) of each quadrature component after band-limiting."""
    bandwidth_hz: float
    """Noise band centred on the carrier (Hz)."""


@dataclass(frozen=True)
class Reverberation:
    """Boundary reverberation from a fan of transmit rays (acoustics/paths/ray_scene.py)."""

    beam_level_db: float
    """The fan covers the transmitter's principal cuts above this level (dB re peak)."""
    rays_per_square_degree: float
    refresh_phase: bool
    """Draw the facets' phases anew each ping."""
    max_range_m: float | None
    """Ignore hits beyond this range (m); None: the end of the record."""


@dataclass(frozen=True)
class Effects:
    """The switches and fidelity settings the ping loop reads (docs/accuracy.md); the echo
    model's (directivity, baffle, spreading, absorption) are in :class:`EchoModel`."""

    synthesis: str
    kernel_length: int
    oversampling: int
    occlusion: bool
    max_bounces: int
    doppler: bool
    doppler_method: str
    doppler_error_db: float
    doppler_bin_hz: float
    stop_and_hop: bool
    arrivals: bool
    """Record every arrival of every ping."""
    arrivals_floor_db: float | None
    """Drop arrivals more than this far (dB) below the ping's strongest; None keeps all."""
    reverberation: Reverberation | None
    """None when reverberation is off or no boundary has a scattering law."""


@dataclass(frozen=True, eq=False)
class Rays:
    """What a run's ray scene is built from: the meshes, built once in the sonar frame at rest
    (the mounting pose), and where they came from (to rebuild them for another pose)."""

    sources: MeshSources
    meshes: tuple
    """:class:`~acoustics.paths.meshes.SceneMesh` of every boundary and mesh target."""
    threads: int | None
    """Threads for ray batches (None: every core)."""
    specular: object
    """The specular search's settings (``effects.specular``)."""

    @property
    def has_mesh_targets(self) -> bool:
        return any(sm.kind == "target" for sm in self.meshes)


@dataclass(frozen=True, eq=False)
class Setup:
    """Everything fixed for a run of one scene, resolved: the ping loop's only input besides
    the ping index and the seed. Frozen and never mutated (what a run fills lives in
    :class:`RunCache`)."""

    sonar: Sonar
    medium: Medium
    pulse: Pulse
    model: EchoModel
    tx_beamwidth_az_rad: float
    tx_beamwidth_el_rad: float
    counting_range_m: tuple
    sampling: Sampling
    noise: Noise
    effects: Effects
    targets: Targets
    rays: Rays | None = None
    """The meshes of the ray-traced scene; None for a scene without meshes."""
    platform: object = None
    """:class:`~acoustics.sonar.platform.PlatformMotion` of a moving platform, else None."""
    interval_s: float = 1.0
    seed: int = 0
    """The scene's seed (``simulate(seed=...)`` overrides it per run)."""

    @property
    def center_frequency_hz(self) -> float:
        """The carrier f0 (Hz)."""
        return self.pulse.center_frequency_hz

    def pose_at(self, ping: int):
        """The sonar's world pose at ping ``ping`` (the mounting pose when nothing moves)."""
        if self.platform is None:
            return self.sonar.pose
        return self.platform.pose(self.sonar.pose, ping * self.interval_s)

    @property
    def counting_volume(self) -> CountingVolume:
        """The default counting volume (processing's definition, :mod:`processing.base.counting_volume`)."""
        return counting_volume(tx_beamwidth_az_rad=self.tx_beamwidth_az_rad,
                               tx_beamwidth_el_rad=self.tx_beamwidth_el_rad,
                               image_range_m=self.counting_range_m)


class RunCache:
    """What one run fills as it goes, kept out of the frozen :class:`Setup`: the ray scene (its
    caster and the rays cast per purpose, the built tiles of a tiled floor in the caster's
    :class:`~acoustics.paths.tiles.TileCache`, a moving sea's time, the reverberation rays and
    lit facets it keeps) and, for a moving sonar among meshes of both frames, the ray scene rebuilt
    for the last pose.

    Parameters
    ----------
    setup : Setup
    log : StageLog, optional
        Building the ray caster is timed as ``rays_build``.
    """

    def __init__(self, setup: Setup, log: StageLog | None = None):
        self.setup = setup
        self.ray_scene = None
        self._moved: dict = {}
        if setup.rays is not None:
            log = log if log is not None else StageLog()
            with log.stage("rays_build"):
                self.ray_scene = self._build(list(setup.rays.meshes))

    def _build(self, meshes):
        from acoustics.paths.ray_scene import build_ray_scene
        s, rays = self.setup, self.setup.rays
        return build_ray_scene(meshes, s.sonar, s.medium, frequency_hz=s.center_frequency_hz,
                               specular=rays.specular, threads=rays.threads)

    def ray_scene_at(self, pose, log: StageLog | None = None):
        """The ray-traced scene for a ping whose sonar is at ``pose``, and the view to query it
        with: ``(ray_scene, view)``.

        The run's scene is built once, in the sonar frame at rest (the mounting pose); a moving
        sonar queries it through ``view``, its ping's sonar frame in that frame (None for a still
        platform, or when every mesh rides with the sonar in the sonar frame). Only a scene that
        mixes world-frame and sonar-frame meshes under a moving platform is rebuilt for each
        pose (its meshes move relative to each other; the last pose's scene is kept).
        """
        rs, setup = self.ray_scene, self.setup
        if rs is None or setup.platform is None:
            return rs, None
        frames = {getattr(sm.spec, "frame", "world") for sm in rs.meshes}
        if frames == {"sonar"}:
            return rs, None
        if frames == {"world"}:
            mount = setup.sonar.pose
            return rs, Pose(mount.to_sonar(pose.position_m), mount.rotation.T @ pose.rotation)
        key = pose.position_m.tobytes() + pose.rotation.tobytes()
        if key not in self._moved:
            from acoustics.paths.meshes import scene_meshes
            self._moved.clear()
            log = log if log is not None else StageLog()
            with log.stage("rays_build"):
                moved = self._build(scene_meshes(setup.rays.sources, pose))
            moved.caster.rays_cast = rs.caster.rays_cast      # one count per run
            self._moved[key] = moved
        return self._moved[key], None


def _tx_beamwidths(key, tx, c, f0):
    def compute():
        m = Medium(sound_speed_m_s=c)
        return (beamwidth(tx, plane="azimuth", medium=m, frequency_hz=f0),
                beamwidth(tx, plane="elevation", medium=m, frequency_hz=f0))
    return per_geometry("tx_beamwidths", (key, c, f0), compute)


def resolve_mesh_sources(scene) -> MeshSources:
    """The boundaries and mesh targets of a scene, with the folder their files are read from."""
    from acoustics.paths.meshes import MeshSources
    src = scene.source_path
    return MeshSources(tuple(scene.boundaries), tuple(scene.targets.meshes),
                       None if src is None else src.parent, str(src or "<scene>"), scene.seed,
                       scene.effects.floor_tiles)


def _resolve_targets(scene, medium: Medium, pose0: Pose) -> Targets:
    """The scene's targets as the ping loop draws them (explicit points in their frame)."""
    from acoustics.frames import spherical_to_cartesian
    points = []
    for t in scene.targets.points:
        if t.position_m is None:
            pos, frame = tuple(float(x) for x in spherical_to_cartesian(
                t.range_m, t.azimuth, t.elevation)), "sonar"
        else:
            pos, frame = tuple(t.position_m), t.frame
        vel = None if t.velocity_m_s is None else tuple(t.velocity_m_s)
        points.append(TargetPoint(frame, pos, vel, t.backscatter, bool(t.random_phase)))
    f0 = scene.signal.center_frequency_hz
    return Targets(tuple(points), tuple(scene.targets.populations), scene.pings.interval_s,
                   pose0, medium.wavenumber_rad_m(f0), scene.seed)


def _resolve_effects(scene) -> Effects:
    fx = scene.effects
    rv = fx.reverberation
    reverb = None
    if rv.enabled and any(getattr(b, "scattering", None) is not None for b in scene.boundaries):
        reverb = Reverberation(rv.beam_level_db, rv.rays_per_square_degree, rv.refresh_phase,
                               rv.max_range_m)
    return Effects(fx.synthesis, fx.kernel_length, fx.oversampling, fx.occlusion,
                   fx.max_bounces, fx.doppler, fx.doppler_method, fx.doppler_error_db,
                   fx.doppler_bin_hz, fx.stop_and_hop, fx.arrivals.enabled,
                   fx.arrivals.floor_db, reverb)


def make_setup(scene, log: StageLog | None = None) -> Setup:
    """Resolve a scene, once per run: its arrays, medium, pulse and echo model, what the ping
    loop reads of each section, and its meshes when it has any.

    Raises
    ------
    acoustics.scene.SceneError
        A mesh, motion file or processing range that cannot be used (one line naming it).
    """
    sonar = build_sonar(scene)
    medium = Medium.from_spec(scene.medium)
    pulse = Pulse.from_spec(scene.signal)
    fx = scene.effects
    model = EchoModel(sonar.transmitter, sonar.receiver.elements, medium,
                      scene.signal.center_frequency_hz, scene.sampling.adc.scale_counts,
                      fx.directivity, tuple(fx.huygens_subdivisions), fx.baffle, fx.spreading,
                      fx.absorption)
    tx = sonar.transmitter
    az, el = _tx_beamwidths(array_key(tx), tx, medium.sound_speed_m_s,
                            scene.signal.center_frequency_hz)
    c, s = medium.sound_speed_m_s, scene.sampling
    window_m = (c * s.time_offset_s / 2, c * (s.time_offset_s + s.samples / s.rate_hz) / 2)
    try:
        rng_m = image_range_of(scene.processing, window_m)
    except ValueError as exc:
        from acoustics.scene.errors import SceneError
        raise SceneError(f"{scene.source_path or scene.name}: {exc}") from None
    platform = None
    pose0 = sonar.pose
    if scene.sonar.motion is not None:
        from acoustics.sonar.platform import PlatformMotion
        platform = PlatformMotion.from_spec(scene.sonar.motion, scene.resolve_path)
        pose0 = platform.pose(sonar.pose, 0.0)
    rays = None
    if scene.boundaries or scene.targets.meshes:
        from acoustics.paths.meshes import scene_meshes
        log = log if log is not None else StageLog()
        sources = resolve_mesh_sources(scene)
        with log.stage("rays_build"):
            meshes = tuple(scene_meshes(sources, sonar.pose))
        rays = Rays(sources, meshes, fx.ray_threads, fx.specular)
    sampling = Sampling(s.rate_hz, s.samples, s.time_offset_s, s.adc.quantize, s.adc.bits)
    noise = Noise(scene.noise.sigma_counts if scene.noise.enabled else 0.0,
                  scene.noise.bandwidth_hz)
    return Setup(sonar, medium, pulse, model, az, el, tuple(float(r) for r in rng_m),
                 sampling, noise, _resolve_effects(scene), _resolve_targets(scene, medium, pose0),
                 rays=rays, platform=platform, interval_s=scene.pings.interval_s, seed=scene.seed)


def counting_volume_of(setup: Setup, positions_sonar_m) -> np.ndarray:
    """True where a sonar-frame position lies in the default counting volume (the one
    processing uses: :func:`processing.base.counting_volume.counting_volume` of the transmitter's 3 dB
    beamwidths and the image's range limits).

    Parameters
    ----------
    setup : Setup
    positions_sonar_m : array_like, shape (n, 3)
        Sonar-frame positions (m).

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    return setup.counting_volume.contains(positions_sonar_m)
