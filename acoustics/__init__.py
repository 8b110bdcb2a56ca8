"""abacus.acoustics — the forward problem: a scene becomes per-element complex echoes.

Public surface (docs/conventions.md for frames, units and signs)::

    load_scene(path) -> Scene                  # raises SceneError
    beamwidth(array, *, plane, level_db=-3.0, medium=None) -> float (rad)
    array_pattern, element_directivity, array_response
    Medium, ElementArray, abacus_transmitter, abacus_receiver, build_sonar
"""
from .arrays import ElementArray, Receiver, abacus_receiver, abacus_transmitter
from .beams import beamwidth, pattern_cut, peak_sidelobe_db, summarize_beam
from .directivity import array_pattern, array_response, element_directivity
from .frames import Pose, cartesian_to_spherical, spherical_to_cartesian
from .medium import Medium, francois_garrison_db_per_m
from .scene import Scene, SceneError, SceneWarning, load_scene
from .sonar import Sonar, build_sonar

__version__ = "0.1.0"

__all__ = ["load_scene", "Scene", "SceneError", "SceneWarning", "beamwidth", "pattern_cut",
           "peak_sidelobe_db", "summarize_beam", "array_pattern", "array_response",
           "element_directivity", "Medium", "francois_garrison_db_per_m", "ElementArray",
           "Receiver", "abacus_transmitter", "abacus_receiver", "Sonar", "build_sonar", "Pose",
           "spherical_to_cartesian", "cartesian_to_spherical", "__version__"]
