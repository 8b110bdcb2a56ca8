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

import math
from pathlib import Path
from typing import Annotated, Literal, Union

from pydantic import (AfterValidator, BeforeValidator, Discriminator, Field, Tag, field_validator,
                      model_validator)

from processing.base.config import (ConfigModel, Count, NonNegativeReal, PositiveCount, PositiveReal,
                               Real)

__all__ = ["MeshSpec", "BoundarySpec", "MeshTargetSpec", "ReverberationSpec", "SpecularSpec",
           "MESH_SUFFIXES", "MAX_EXTENT_M", "Coordinate", "Position3", "Direction3", "Size",
           "Resolution", "Degrees", "BREAKING_STEEPNESS", "Bounded"]

#: file types read through trimesh
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")

# ------------------------------------------------------------------ bounded quantities
# Every length, position and resolution of a scene is bounded, so that no value the schema
# accepts overflows later (a size of 1e300 squared, a resolution of 1e-300 divided into a size,
# a scale of 1e300 on a vertex): the bounds are generous for a sonar scene and the same wherever
# the quantity appears (sonar, targets, meshes).

#: the largest position or size (m) a scene may hold: 100 km from the world origin
MAX_EXTENT_M = 1e5
#: a wave steeper than this (height / wavelength = 2a/λ) breaks (Stokes' limit, ≈ 1/7)
BREAKING_STEEPNESS = 1.0 / 7.0


def _finite_number(v):
    if isinstance(v, float) and not math.isfinite(v):
        raise ValueError("must be a finite number (not inf or nan)")
    return v


def Bounded(lo: float, hi: float, *, positive: bool = False):
    """A real number within [lo, hi]: a number (no string), finite, its bounds in the JSON
    Schema as ``minimum`` and ``maximum`` (so a type, usable inside tuples). ``positive``: a
    size, whose value of 0 or less is refused as "must be > 0" before its lower bound is
    checked."""
    if not positive:
        return Annotated[float, Field(strict=True, ge=lo, le=hi), BeforeValidator(_finite_number)]

    def at_least(v):
        if v < lo:
            raise ValueError(f"must be >= {lo:g}")
        return v
    return Annotated[float, Field(strict=True, gt=0, le=hi, json_schema_extra={"minimum": lo}),
                     BeforeValidator(_finite_number), AfterValidator(at_least)]


#: a position (m) along one axis, within ±100 km
Coordinate = Bounded(-MAX_EXTENT_M, MAX_EXTENT_M)
Position3 = tuple[Coordinate, Coordinate, Coordinate]
#: a direction's component (any length, normalised where used)
Direction3 = tuple[Bounded(-1e6, 1e6), Bounded(-1e6, 1e6), Bounded(-1e6, 1e6)]
#: a size (m) of a shape: 0.1 mm to 100 km
Size = Bounded(1e-4, MAX_EXTENT_M, positive=True)
#: a grid step (m): 1 mm to 1 km
Resolution = Bounded(1e-3, 1e3, positive=True)
#: an angle written and held in degrees, within ±360°
Degrees = Bounded(-360.0, 360.0)


class Transform(ConfigModel):
    """Applied after the shape is built: scale, then rotate (x, then y, then z axis, degrees,
    right-handed), then translate."""

    scale: Bounded(1e-3, 1e3, positive=True) = 1.0
    """Uniform scale, 0.001 (a file in millimetres) to 1000."""
    rotate_deg: tuple[Degrees, Degrees, Degrees] = (0.0, 0.0, 0.0)
    translate_m: Position3 = (0.0, 0.0, 0.0)


class _Shape(ConfigModel):
    transform: Transform = Transform()


class PlaneShape(_Shape):
    """A flat rectangle: centre, unit normal (any length, normalised), side lengths."""

    shape: Literal["plane"] = "plane"
    center_m: Position3 = (0.0, 0.0, 0.0)
    normal: Direction3 = (0.0, 0.0, 1.0)
    size_m: tuple[Size, Size] = (200.0, 200.0)
    segments: tuple[PositiveCount, PositiveCount] = (1, 1)
    """Triangle grid resolution (a plane needs only 1 x 1; more only for the view)."""


class RoughFloorShape(_Shape):
    """A seeded random height field z = depth + slope·(x, y) + h(x, y) in the world frame, h a
    Gaussian random field with RMS height and correlation length (Gaussian spectrum)."""

    shape: Literal["rough_floor"] = "rough_floor"
    depth_m: Coordinate = 30.0
    center_m: tuple[Coordinate, Coordinate] = (0.0, 0.0)
    size_m: tuple[Size, Size] = (60.0, 60.0)
    resolution_m: Resolution = 0.25
    rms_height_m: NonNegativeReal = Field(0.05, le=100.0)
    correlation_length_m: Bounded(1e-3, MAX_EXTENT_M, positive=True) = 1.0
    """At most half the floor's smaller side (a longer one is a tilt, not a roughness: the
    field's spectrum would hold nothing the grid can show)."""
    slope: tuple[Bounded(-100.0, 100.0), Bounded(-100.0, 100.0)] = (0.0, 0.0)
    """dz/dx and dz/dy."""
    seed: Count = 0
    """Added to the scene's seed: the floor is the same for every ping."""

    @model_validator(mode="after")
    def _correlation_fits(self):
        half = min(self.size_m) / 2
        if self.rms_height_m > 0 and self.correlation_length_m > half:
            raise ValueError(f"correlation_length_m {self.correlation_length_m:g} m exceeds half "
                             f"the floor's smaller side ({half:g} m): at most {half:g} m, or a "
                             f"larger size_m")
        return self


class HeightGridShape(_Shape):
    """Heights z (m, world frame) from a small grid file (.npy or .csv), rows along y."""

    shape: Literal["height_grid"] = "height_grid"
    file: str
    spacing_m: tuple[Resolution, Resolution]
    origin_m: tuple[Coordinate, Coordinate] = (0.0, 0.0)


class _MovingSea(_Shape):
    """A sea surface that moves between pings (acoustics/paths/sea_surface.py): a height field in
    the world frame, z = mean_level_m − η(x, y, t), t = time_offset_s + the ping's time."""

    center_m: tuple[Coordinate, Coordinate] = (0.0, 0.0)
    size_m: tuple[Size, Size] = (60.0, 60.0)
    resolution_m: Bounded(0.01, 1e3, positive=True) = 0.25
    """Grid step: the mesh resolution, an accuracy knob (docs/accuracy.md)."""
    mean_level_m: Coordinate = 0.0
    """z of the still surface (world frame, z down); the sonar and every target must stay below
    the moving surface at every ping."""
    water_depth_m: Bounded(0.1, 12000.0, positive=True) | None = None
    """Depth for the dispersion relation ω² = g k tanh(k d); null: deep water."""
    time_offset_s: Real = Field(0.0, ge=-1e9, le=1e9)
    """The sea's time at ping 0 (ping p shows the sea at time_offset_s + p x pings.interval_s)."""


class WindSeaShape(_MovingSea):
    """A wind sea: Pierson–Moskowitz (fully developed) or, with a fetch, JONSWAP; directional
    spreading cos^2s(Δθ/2); seeded phases."""

    shape: Literal["wind_sea"] = "wind_sea"
    wind_speed_m_s: PositiveReal = Field(10.0, le=40.0)
    """U10, the wind speed 10 m above the sea."""
    direction_deg: Degrees = 0.0
    """Direction the waves travel to, from the world x axis towards y."""
    fetch_km: Bounded(0.01, 10000.0, positive=True) | None = None
    """Fetch for JONSWAP (10 m to 10 000 km); null: the fully developed sea (Pierson–Moskowitz)."""
    spreading: PositiveReal = Field(10.0, le=1000.0)
    """s of the cos^2s(Δθ/2) directional spreading (larger: longer crests)."""
    seed: Count = 0
    """Added to the scene's seed: the same sea at every ping and on every worker."""


class SwellWave(ConfigModel):
    amplitude_m: NonNegativeReal = Field(le=30.0)
    """Half the crest-to-trough height (m), at most 30 m and at most λ/14: a wave steeper than
    height/λ = 1/7 breaks."""
    wavelength_m: Bounded(0.02, MAX_EXTENT_M, positive=True)
    """2 cm (shorter ripples are capillary, not gravity waves) to 100 km."""
    direction_deg: Degrees = 0.0
    """Direction of travel, from the world x axis towards y."""
    phase_deg: Degrees = 0.0
    """Phase of the crest at x = y = 0, t = 0 (0: a crest there)."""

    @model_validator(mode="after")
    def _not_breaking(self):
        steepness = 2 * self.amplitude_m / self.wavelength_m
        if steepness > BREAKING_STEEPNESS:
            raise ValueError(f"amplitude_m {self.amplitude_m:g} m on a {self.wavelength_m:g}-m wave "
                             f"is a height/wavelength of {steepness:.3g}: waves break beyond 1/7, "
                             f"so amplitude_m is at most wavelength_m/14 = "
                             f"{self.wavelength_m * BREAKING_STEEPNESS / 2:.4g} m")
        return self


class SwellShape(_MovingSea):
    """A swell: one or a few travelling sinusoids (amplitude, wavelength, direction, phase)."""

    shape: Literal["swell"] = "swell"
    waves: tuple[SwellWave, ...] = Field(json_schema_extra={"minItems": 1, "maxItems": 64})
    """One to 64 waves."""

    @field_validator("waves")
    @classmethod
    def _some_waves(cls, v):
        # checked here rather than as the tuple's length bounds, which pydantic would also report
        # (as "at least 1 item") for a list whose one wave has a bad value
        if not 1 <= len(v) <= 64:
            raise ValueError(f"give 1 to 64 waves, not {len(v)}")
        return v


class SphereShape(_Shape):
    shape: Literal["sphere"] = "sphere"
    center_m: Position3 = (0.0, 0.0, 0.0)
    radius_m: Size
    subdivisions: PositiveCount = Field(4, le=8)
    """Icosphere subdivisions: 4 -> 5120 faces, 5 -> 20480, 6 -> 81920."""


class SpheroidShape(_Shape):
    """An ellipsoid with semi-axes along x, y, z (rotate it with ``transform``)."""

    shape: Literal["spheroid"] = "spheroid"
    center_m: Position3 = (0.0, 0.0, 0.0)
    semi_axes_m: tuple[Size, Size, Size]
    subdivisions: PositiveCount = Field(4, le=8)


class BoxShape(_Shape):
    shape: Literal["box"] = "box"
    center_m: Position3 = (0.0, 0.0, 0.0)
    size_m: tuple[Size, Size, Size]


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
    mu_db: Real = Field(-27.0, ge=-150.0, le=0)
    """Lambert parameter 10 log10 μ (sand about −27 dB, mud −35 dB, rock −17 dB)."""


class ConstantReflection(ConfigModel):
    """A fixed specular reflection coefficient (−1: the pressure-release sea surface)."""

    model: Literal["constant"] = "constant"
    coefficient: Real = Field(-1.0, ge=-1.0, le=1.0)


class RayleighReflection(ConfigModel):
    """Rayleigh's plane-wave coefficient of a fluid half-space (complex beyond critical)."""

    model: Literal["rayleigh"] = "rayleigh"
    density_kg_m3: Bounded(1.0, 30000.0, positive=True) = 1900.0
    sound_speed_m_s: Bounded(100.0, 20000.0, positive=True) = 1700.0
    water_density_kg_m3: Bounded(900.0, 1100.0, positive=True) = 1027.0


Reflection = Annotated[Union[Annotated[ConstantReflection, Tag("constant")],
                             Annotated[RayleighReflection, Tag("rayleigh")]],
                       Discriminator("model")]


class BoundarySpec(ConfigModel):
    """A boundary mesh (sea surface, sea floor, rock) and its acoustics.

    Specular paths: planar meshes by image sources (up to ``effects.max_bounces`` bounces
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
    max_range_m: PositiveReal | None = Field(None, le=MAX_EXTENT_M)
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
    beam_level_db: Real | None = Field(None, lt=0, ge=-60)
    """Search only where the transmitter's principal cuts are above this level (dB re peak,
    sidelobes included, as the reverberation fan): transmit legs bounce only on facets inside
    that fan, and receive legs are searched only for targets inside it or with a transmit leg
    that bounces (every other path leaves the transmitter below the level). null: every facet
    for every target (the reference). An accuracy knob (docs/accuracy.md, "Specular fan")."""
    near_facets: bool = False
    """With ``beam_level_db``: a block of facets seen from a leg's start under more than
    0.05 rad (a sea just above the sonar) is searched only in its facets that reach into the
    fan themselves, not in every facet of a block whose sphere does (near the sonar a block's
    sphere spans far more than the fan). An accuracy knob (docs/accuracy.md, "Specular fan")."""
