"""Scene-file sections for meshes: boundaries (sea surface, sea floor, rocks) and mesh targets.

A mesh is a file trimesh reads (OBJ, STL, PLY, GLB, ... — path relative to the scene file) or a
procedural shape written in the YAML itself, so that scenes stay small in version control:
``plane``, ``rough_floor`` (seeded random height field with a Gaussian spectrum, optionally
sloping), ``height_grid`` (a small .npy or .csv grid of heights), ``sphere``, ``spheroid``,
``box``, and two sea surfaces that move between pings: ``wind_sea`` (a wave spectrum of the wind)
and ``swell`` (a few travelling sinusoids). Every mesh takes an optional ``transform`` (scale, then rotate, then translate).
Boundaries live in the world frame by default (z down, the surface at z = 0); mesh targets may use
either frame.
"""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal, Union

from pydantic import Discriminator, Field, Tag, field_validator, model_validator

from processing.base.config import (ConfigModel, Count, NonNegativeReal, PositiveCount, PositiveReal,
                               Real, Vec3)

__all__ = ["MeshSpec", "BoundarySpec", "MeshTargetSpec", "ReverberationSpec", "SpecularSpec",
           "MESH_SUFFIXES"]

#: file types read through trimesh
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")


class Transform(ConfigModel):
    """Applied after the shape is built: scale, then rotate (x, then y, then z axis, degrees,
    right-handed), then translate."""

    scale: PositiveReal = 1.0
    rotate_deg: Vec3 = (0.0, 0.0, 0.0)
    translate_m: Vec3 = (0.0, 0.0, 0.0)


class _Shape(ConfigModel):
    transform: Transform = Transform()


class PlaneShape(_Shape):
    """A flat rectangle: centre, unit normal (any length, normalised), side lengths."""

    shape: Literal["plane"] = "plane"
    center_m: Vec3 = (0.0, 0.0, 0.0)
    normal: Vec3 = (0.0, 0.0, 1.0)
    size_m: tuple[PositiveReal, PositiveReal] = (200.0, 200.0)
    segments: tuple[PositiveCount, PositiveCount] = (1, 1)
    """Triangle grid resolution (a plane needs only 1 x 1; more only for the view)."""


class RoughFloorShape(_Shape):
    """A seeded random height field z = depth + slope·(x, y) + h(x, y) in the world frame, h a
    Gaussian random field with RMS height and correlation length (Gaussian spectrum)."""

    shape: Literal["rough_floor"] = "rough_floor"
    depth_m: Real = 30.0
    center_m: tuple[Real, Real] = (0.0, 0.0)
    size_m: tuple[PositiveReal, PositiveReal] = (60.0, 60.0)
    resolution_m: PositiveReal = 0.25
    rms_height_m: NonNegativeReal = 0.05
    correlation_length_m: PositiveReal = 1.0
    slope: tuple[Real, Real] = (0.0, 0.0)
    """dz/dx and dz/dy."""
    seed: Count = 0
    """Added to the scene's seed: the floor is the same for every ping."""


class HeightGridShape(_Shape):
    """Heights z (m, world frame) from a small grid file (.npy or .csv), rows along y."""

    shape: Literal["height_grid"] = "height_grid"
    file: str
    spacing_m: tuple[PositiveReal, PositiveReal]
    origin_m: tuple[Real, Real] = (0.0, 0.0)


class _MovingSea(_Shape):
    """A sea surface that moves between pings (acoustics/paths/sea_surface.py): a height field in
    the world frame, z = mean_level_m − η(x, y, t), t = time_offset_s + the ping's time."""

    center_m: tuple[Real, Real] = (0.0, 0.0)
    size_m: tuple[PositiveReal, PositiveReal] = (60.0, 60.0)
    resolution_m: PositiveReal = 0.25
    """Grid step: the mesh resolution, an accuracy knob (docs/accuracy.md)."""
    mean_level_m: Real = 0.0
    """z of the still surface (world frame, z down)."""
    water_depth_m: PositiveReal | None = None
    """Depth for the dispersion relation ω² = g k tanh(k d); null: deep water."""
    time_offset_s: Real = 0.0
    """The sea's time at the first ping."""


class WindSeaShape(_MovingSea):
    """A wind sea: Pierson–Moskowitz (fully developed) or, with a fetch, JONSWAP; directional
    spreading cos^2s(Δθ/2); seeded phases."""

    shape: Literal["wind_sea"] = "wind_sea"
    wind_speed_m_s: PositiveReal = Field(10.0, le=40.0)
    """U10, the wind speed 10 m above the sea."""
    direction_deg: Real = 0.0
    """Direction the waves travel to, from the world x axis towards y."""
    fetch_km: PositiveReal | None = None
    """Fetch for JONSWAP; null: the fully developed sea (Pierson–Moskowitz)."""
    spreading: PositiveReal = 10.0
    """s of the cos^2s(Δθ/2) directional spreading (larger: longer crests)."""
    seed: Count = 0
    """Added to the scene's seed: the same sea at every ping and on every worker."""


class SwellWave(ConfigModel):
    amplitude_m: NonNegativeReal
    wavelength_m: PositiveReal
    direction_deg: Real = 0.0
    """Direction of travel, from the world x axis towards y."""
    phase_deg: Real = 0.0
    """Phase of the crest at x = y = 0, t = 0 (0: a crest there)."""


class SwellShape(_MovingSea):
    """A swell: one or a few travelling sinusoids (amplitude, wavelength, direction, phase)."""

    shape: Literal["swell"] = "swell"
    waves: tuple[SwellWave, ...] = Field(min_length=1, max_length=64)


class SphereShape(_Shape):
    shape: Literal["sphere"] = "sphere"
    center_m: Vec3 = (0.0, 0.0, 0.0)
    radius_m: PositiveReal
    subdivisions: PositiveCount = Field(4, le=8)
    """Icosphere subdivisions: 4 -> 5120 faces, 5 -> 20480, 6 -> 81920."""


class SpheroidShape(_Shape):
    """An ellipsoid with semi-axes along x, y, z (rotate it with ``transform``)."""

    shape: Literal["spheroid"] = "spheroid"
    center_m: Vec3 = (0.0, 0.0, 0.0)
    semi_axes_m: tuple[PositiveReal, PositiveReal, PositiveReal]
    subdivisions: PositiveCount = Field(4, le=8)


class BoxShape(_Shape):
    shape: Literal["box"] = "box"
    center_m: Vec3 = (0.0, 0.0, 0.0)
    size_m: tuple[PositiveReal, PositiveReal, PositiveReal]


class FileShape(_Shape):
    """A mesh file, relative to the scene file."""

    shape: Literal["file"] = "file"
    file: str
    repair: bool = True
    """Merge duplicate vertices, drop degenerate faces, make normals consistent (reported)."""

    @field_validator("file")
    @classmethod
    def _suffix(cls, v):
        if Path(v).suffix.lower() not in MESH_SUFFIXES:
            raise ValueError(f"mesh files must end in one of {', '.join(MESH_SUFFIXES)}")
        return v


MeshSpec = Annotated[Union[Annotated[PlaneShape, Tag("plane")],
                           Annotated[RoughFloorShape, Tag("rough_floor")],
                           Annotated[HeightGridShape, Tag("height_grid")],
                           Annotated[SphereShape, Tag("sphere")],
                           Annotated[SpheroidShape, Tag("spheroid")],
                           Annotated[BoxShape, Tag("box")],
                           Annotated[WindSeaShape, Tag("wind_sea")],
                           Annotated[SwellShape, Tag("swell")],
                           Annotated[FileShape, Tag("file")]],
                     Discriminator("shape")]


class Lambert(ConfigModel):
    """Lambert's law: s_b = μ sin² θ_g per unit area (θ_g the grazing angle), μ in dB."""

    law: Literal["lambert"] = "lambert"
    mu_db: Real = Field(-27.0, le=0)
    """Lambert parameter 10 log10 μ (sand about −27 dB, mud −35 dB, rock −17 dB)."""


class ConstantReflection(ConfigModel):
    """A fixed specular reflection coefficient (−1: the pressure-release sea surface)."""

    model: Literal["constant"] = "constant"
    coefficient: Real = Field(-1.0, ge=-1.0, le=1.0)


class RayleighReflection(ConfigModel):
    """Rayleigh's plane-wave coefficient of a fluid half-space (complex beyond critical)."""

    model: Literal["rayleigh"] = "rayleigh"
    density_kg_m3: PositiveReal = 1900.0
    sound_speed_m_s: PositiveReal = 1700.0
    water_density_kg_m3: PositiveReal = 1027.0


Reflection = Annotated[Union[Annotated[ConstantReflection, Tag("constant")],
                             Annotated[RayleighReflection, Tag("rayleigh")]],
                       Discriminator("model")]


class BoundarySpec(ConfigModel):
    """A boundary mesh (sea surface, sea floor, rock) and its acoustics.

    Specular paths: planar meshes by image sources (up to ``effects.multipath_order`` bounces
    per leg); any other mesh by its specular points (one bounce per leg,
    acoustics/paths/specular.py)."""

    name: str = Field(min_length=1)
    role: Literal["surface", "floor", "obstacle"] = "floor"
    frame: Literal["world", "sonar"] = "world"
    mesh: MeshSpec
    scattering: Lambert | None = None
    """Diffuse backscatter (reverberation); default: floor −27 dB, obstacle −17 dB, surface none."""
    reflection: Reflection | None = None
    """Specular reflection (multipath); default: surface −1, floor Rayleigh (sand), obstacle +1."""

    @model_validator(mode="before")
    @classmethod
    def _defaults(cls, data):
        if isinstance(data, dict):
            role = data.get("role", "floor")
            data = dict(data)
            if "scattering" not in data:
                data["scattering"] = {"floor": {"law": "lambert", "mu_db": -27.0},
                                      "obstacle": {"law": "lambert", "mu_db": -17.0}}.get(role)
            if "reflection" not in data:
                data["reflection"] = {"surface": {"model": "constant", "coefficient": -1.0},
                                      "floor": {"model": "rayleigh"},
                                      "obstacle": {"model": "constant", "coefficient": 1.0}}.get(role)
        return data

    @model_validator(mode="after")
    def _moving_sea_in_world(self):
        if self.mesh.shape in ("wind_sea", "swell") and self.frame != "world":
            raise ValueError(f"a {self.mesh.shape} surface lives in the world frame (z down): "
                             f"set frame: world")
        return self


class MeshTargetSpec(ConfigModel):
    """A target whose echo comes from its geometry: the physical-optics (Kirchhoff) integral
    over its ensonified, visible facets, each integrated exactly (Gordon's formula)."""

    name: str = Field(min_length=1)
    frame: Literal["world", "sonar"] = "world"
    mesh: MeshSpec
    boundary: Literal["rigid", "pressure_release"] = "rigid"

    @model_validator(mode="after")
    def _no_moving_sea(self):
        if self.mesh.shape in ("wind_sea", "swell"):
            raise ValueError(f"a {self.mesh.shape} is a sea surface: put it under boundaries")
        return self


class ReverberationSpec(ConfigModel):
    """Boundary echoes: rays from the transmitter through its beam; every first hit on a boundary
    with a scattering law becomes a facet scatterer."""

    enabled: bool = False
    beam_level_db: Real = Field(-20.0, lt=0, ge=-60)
    """Rays fill the azimuth x elevation rectangle outside which the transmitter's principal
    cuts stay below this level (dB re peak, sidelobes included): an accuracy knob."""
    rays_per_square_degree: PositiveReal = Field(400.0, le=1e6)
    """Ray density: the accuracy knob (docs/accuracy.md)."""
    refresh_phase: bool = False
    """Draw the facets' random phases anew each ping (a moving surface); false: frozen, as for
    static geometry."""
    max_range_m: PositiveReal | None = None
    """Ignore hits beyond this range; default the end of the record."""


class SpecularSpec(ConfigModel):
    """Specular paths off curved boundaries (acoustics/paths/specular.py)."""

    newton_iterations: Count = Field(8, le=50)
    """Refinement of each bounce point on the smooth surface the mesh samples (0: the linear
    estimate on its facet): an accuracy knob (docs/accuracy.md)."""
    exact_surface: bool = True
    """Sea surfaces (``wind_sea``, ``swell``): refine bounce points and take their levels on the
    exact surface, the mesh only finding them and deciding visibility; false: on the mesh
    (Phong-smooth facets), whose error the mesh resolution sets (docs/accuracy.md)."""
    focusing_limit_db: Real = Field(20.0, ge=0.0, le=60.0)
    """Largest gain of a curved mirror over a flat one (dB): geometrical optics diverges at a
    caustic; paths held at the limit are counted in the run record."""
