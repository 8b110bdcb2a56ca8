"""Scene files: the one place a scene is read, validated and resolved.

``schema`` (the root :class:`Scene` and small sections), ``sonar_spec``, ``targets_spec``,
``meshes_spec`` (one module per large section), ``load`` (YAML → validated Scene),
``checks`` (physics warnings) and ``errors``.
"""
from acoustics.scene.errors import SceneError, SceneWarning
from acoustics.scene.load import (key_tuple, load_scene, mesh_files, scene_from_resolved_text, scene_from_text,
                                  validate_scene)
from acoustics.scene.schema import SCHEMA_VERSION, Scene, json_schema, json_schema_text
from acoustics.scene.checks import cross_check

__all__ = ["SCHEMA_VERSION", "Scene", "SceneError", "SceneWarning", "load_scene", "scene_from_text",
           "validate_scene", "scene_from_resolved_text", "json_schema", "json_schema_text", "cross_check", "mesh_files",
           "key_tuple"]
