"""acoustics — the forward model (abacus' lower layer): a scene becomes per-element complex echoes.

The stages, one sub-package each (docs/architecture.md)::

    scene/       scene files: schema, loading, checks          -> Scene
    sonar/       the ABACUS preset, arrays, directivity, beams, pulse, calibration
    targets/     point targets per ping (explicit points, populations)
    paths/       Embree ray casting: occlusion, multipath, reverberation, mesh targets
    synthesis/   arrivals -> per-element complex baseband samples, noise, ADC
    simulation/  the run: setup, one ping, the dataset it becomes

Public surface (docs/api.md; imported on first use, so ``import acoustics`` is cheap)::

    load_scene(path) -> Scene                  # raises SceneError
    simulate(scene, *, pings=None, seed=None) -> xarray.DataTree   # scene: a Scene, path or name; pings: n or indices
    beamwidth(array, *, plane, level_db=-3.0, medium=None) -> float (rad)
    Medium, ElementArray, abacus_transmitter, abacus_receiver, build_sonar, ...
"""
from __future__ import annotations

from processing.base.lazy import distribution_version, public_api

__version__ = distribution_version("abacus")

#: public name -> module that defines it
_API = {
    "load_scene": "acoustics.scene.load", "scene_from_text": "acoustics.scene.load",
    "Scene": "acoustics.scene.schema", "SceneError": "acoustics.scene.errors",
    "SceneWarning": "acoustics.scene.errors",
    "simulate": "acoustics.simulation.run",
    "beamwidth": "acoustics.sonar.beams", "pattern_cut": "acoustics.sonar.beams",
    "peak_sidelobe_db": "acoustics.sonar.beams", "summarize_beam": "acoustics.sonar.beams",
    "array_pattern": "acoustics.sonar.directivity", "array_response": "acoustics.sonar.directivity",
    "element_directivity": "acoustics.sonar.directivity",
    "ElementArray": "acoustics.sonar.arrays", "Receiver": "acoustics.sonar.arrays",
    "abacus_transmitter": "acoustics.sonar.arrays", "abacus_receiver": "acoustics.sonar.arrays",
    "Sonar": "acoustics.sonar.build", "build_sonar": "acoustics.sonar.build",
    "Pulse": "acoustics.sonar.pulse",
    "Medium": "acoustics.medium", "francois_garrison_db_per_m": "acoustics.medium",
    "mackenzie_sound_speed_m_s": "acoustics.medium",
    "Pose": "acoustics.frames", "spherical_to_cartesian": "acoustics.frames",
    "cartesian_to_spherical": "acoustics.frames",
}

__getattr__, __dir__, __all__ = public_api("acoustics", _API, globals(), extra=["__version__"])
