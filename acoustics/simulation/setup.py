"""What a simulation fixes once per run: arrays, medium, pulse, echo model, ray scene.

Geometry-only results (transmit beamwidths, the calibration) are cached per process by the
bytes of the geometry (:func:`acoustics.sonar.cache.per_geometry`), so scenes rebuilt from
the same file hit the cache.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from acoustics.medium import Medium
from acoustics.simulation.stages import StageLog
from acoustics.sonar.beams import beamwidth
from acoustics.sonar.build import Sonar, build_sonar
from acoustics.sonar.cache import array_key, per_geometry
from acoustics.sonar.pulse import Pulse
from acoustics.synthesis.arrivals import EchoModel
from processing.base.counting_volume import CountingVolume, counting_volume, image_range_of

__all__ = ["Setup", "make_setup", "counting_volume_of"]


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
    platform: object = None
    """:class:`~acoustics.sonar.platform.PlatformMotion` of a moving platform, else None."""
    interval_s: float = 1.0
    _moving_rays: dict = field(default_factory=dict, repr=False)

    def pose_at(self, ping: int):
        """The sonar's world pose at ping ``ping`` (the mounting pose when nothing moves)."""
        if self.platform is None:
            return self.sonar.pose
        return self.platform.pose(self.sonar.pose, ping * self.interval_s)

    def ray_scene_at(self, scene, pose, log: StageLog | None = None):
        """The ray-traced scene for a ping whose sonar is at ``pose``, and the view to query it
        with: ``(ray_scene, view)``.

        The run's scene is built once, in the sonar frame at rest (the mounting pose); a moving
        sonar queries it through ``view``, its ping's sonar frame in that frame (None for a still
        platform, or when every mesh rides with the sonar in the sonar frame). Only a scene that
        mixes world-frame and sonar-frame meshes under a moving platform is rebuilt for each
        pose (its meshes move relative to each other; the last pose's scene is kept).
        """
        rs = self.ray_scene
        if rs is None or self.platform is None:
            return rs, None
        frames = {getattr(sm.spec, "frame", "world") for sm in rs.meshes}
        if frames == {"sonar"}:
            return rs, None
        if frames == {"world"}:
            from acoustics.frames import Pose
            mount = self.sonar.pose
            return rs, Pose(mount.to_sonar(pose.position_m), mount.rotation.T @ pose.rotation)
        key = pose.position_m.tobytes() + pose.rotation.tobytes()
        if key not in self._moving_rays:
            from acoustics.paths.ray_scene import build_ray_scene
            self._moving_rays.clear()
            log = log if log is not None else StageLog()
            with log.stage("rays_build"):
                moved = build_ray_scene(scene, self.sonar, self.medium, pose)
            moved.caster.rays_cast = rs.caster.rays_cast      # one count per run
            self._moving_rays[key] = moved
        return self._moving_rays[key], None

    @property
    def counting_volume(self) -> CountingVolume:
        """The default counting volume (processing's definition, :mod:`processing.base.counting_volume`)."""
        return counting_volume(tx_beamwidth_az_rad=self.tx_beamwidth_az_rad,
                               tx_beamwidth_el_rad=self.tx_beamwidth_el_rad,
                               image_range_m=self.counting_range_m)


def _tx_beamwidths(key, tx, c, f0):
    def compute():
        m = Medium(sound_speed_m_s=c)
        return (beamwidth(tx, plane="azimuth", medium=m, frequency_hz=f0),
                beamwidth(tx, plane="elevation", medium=m, frequency_hz=f0))
    return per_geometry("tx_beamwidths", (key, c, f0), compute)


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
    if scene.sonar.motion is not None:
        from acoustics.sonar.platform import PlatformMotion
        platform = PlatformMotion.from_spec(scene.sonar.motion, scene.resolve_path)
    ray_scene = None
    if scene.boundaries or scene.targets.meshes:
        from acoustics.paths.ray_scene import build_ray_scene
        log = log if log is not None else StageLog()
        with log.stage("rays_build"):
            ray_scene = build_ray_scene(scene, sonar, medium)
    setup = Setup(sonar, medium, pulse, model, az, el, tuple(float(r) for r in rng_m),
                  ray_scene=ray_scene, platform=platform, interval_s=scene.pings.interval_s)
    return setup


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
