"""The ``targets`` section of a scene file: point targets, populations and mesh targets."""
from __future__ import annotations

import math
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import Discriminator, Field, Tag, model_validator

from acoustics.scene.meshes_spec import MeshTargetSpec
from processing.config import (AngleDeg, AngleRangeDeg, ConfigModel, Count, NonNegativeReal,
                               PositiveReal, Real, Vec3)

__all__ = ["UnitTS", "FixedTS", "RayleighTS", "Backscatter", "PointTarget", "CuboidPopulation",
           "SectorPopulation", "Population", "TargetsSpec", "Interval"]

Interval = tuple[Real, Real]


class UnitTS(ConfigModel):
    """Unit reflector: backscatter amplitude ρ = 1 m (σ_bs = 1 m², TS = 0 dB)."""

    model: Literal["unit"] = "unit"


class FixedTS(ConfigModel):
    """Fixed target strength TS (dB re 1 m²): ρ = 10^(TS/20) m."""

    model: Literal["fixed"] = "fixed"
    ts_db: Real = Field(ge=-150, le=40)


class RayleighTS(ConfigModel):
    """Rayleigh-distributed amplitude ρ bounded to [lo, hi] (thesis §2.4.1, §6.3.3): drawn
    from the Rayleigh law of scale ``scale_m`` truncated to [lo, hi] (inverse CDF)."""

    model: Literal["rayleigh"] = "rayleigh"
    scale_m: PositiveReal = 0.5
    """Rayleigh scale (m); the untruncated mean is scale·√(π/2)."""
    lo_m: NonNegativeReal = 0.25
    hi_m: PositiveReal = 1.25

    @model_validator(mode="after")
    def _bounds(self):
        if not self.lo_m < self.hi_m:
            raise ValueError("lo_m must be below hi_m")
        return self


Backscatter = Annotated[Union[Annotated[UnitTS, Tag("unit")], Annotated[FixedTS, Tag("fixed")],
                              Annotated[RayleighTS, Tag("rayleigh")]],
                        Discriminator("model")]


class PointTarget(ConfigModel):
    """One point target, in the sonar frame as ⟨r, θ, φ⟩ (the thesis' notation) or by
    Cartesian position in the sonar or world frame."""

    frame: Literal["sonar", "world"] = "sonar"
    range_m: PositiveReal | None = None
    azimuth: AngleDeg(-180, 180) | None = Field(None, alias="azimuth_deg")
    elevation: AngleDeg(-90, 90) | None = Field(None, alias="elevation_deg")
    position_m: Vec3 | None = None
    backscatter: Backscatter = UnitTS()
    random_phase: bool = False
    """Give the echo a uniformly random phase (seeded per ping)."""
    label: str = ""

    @model_validator(mode="after")
    def _one_position(self):
        spherical = (self.range_m, self.azimuth, self.elevation)
        if self.position_m is not None:
            if any(v is not None for v in spherical):
                raise ValueError("give either position_m or range_m/azimuth_deg/elevation_deg, "
                                 "not both")
        else:
            if self.frame != "sonar":
                raise ValueError("a world-frame target needs position_m: [x, y, z]")
            if any(v is None for v in spherical):
                raise ValueError("give position_m, or all of range_m, azimuth_deg and "
                                 "elevation_deg")
        return self


class _Population(ConfigModel):
    count: Count | None = None
    density_per_m3: NonNegativeReal | None = None
    redraw: bool = True
    """Draw new positions every ping (true) or keep one draw for the whole run."""
    backscatter: Backscatter = UnitTS()
    random_phase: bool = False
    label: str = ""

    @model_validator(mode="after")
    def _count_or_density(self):
        if (self.count is None) == (self.density_per_m3 is None):
            raise ValueError("give exactly one of count or density_per_m3")
        return self


class CuboidPopulation(_Population):
    """Targets uniform in an axis-aligned cuboid of the world or sonar frame (in the
    world frame z is depth)."""

    kind: Literal["uniform_cuboid"] = "uniform_cuboid"
    frame: Literal["world", "sonar"] = "world"
    x_m: Interval
    y_m: Interval
    z_m: Interval

    @model_validator(mode="after")
    def _ordered(self):
        for key in ("x_m", "y_m", "z_m"):
            lo, hi = getattr(self, key)
            if not lo < hi:
                raise ValueError(f"{key} must be [low, high] with low < high")
        return self

    @property
    def volume_m3(self) -> float:
        return float(np.prod([b - a for a, b in (self.x_m, self.y_m, self.z_m)]))


class SectorPopulation(_Population):
    """Targets uniform (by volume) in a sonar-frame sector of range, azimuth, elevation."""

    kind: Literal["uniform_sector"] = "uniform_sector"
    range_m: Interval
    azimuth: AngleRangeDeg(-90, 90) = Field(alias="azimuth_deg")
    elevation: AngleRangeDeg(-90, 90) = Field(alias="elevation_deg")

    @model_validator(mode="after")
    def _ordered(self):
        lo, hi = self.range_m
        if not 0 <= lo < hi:
            raise ValueError("range_m must be [near, far] with 0 <= near < far")
        return self

    @property
    def volume_m3(self) -> float:
        (r0, r1), (a0, a1), (e0, e1) = self.range_m, self.azimuth, self.elevation
        return (r1**3 - r0**3) / 3.0 * (a1 - a0) * (math.sin(e1) - math.sin(e0))


Population = Annotated[Union[Annotated[CuboidPopulation, Tag("uniform_cuboid")],
                             Annotated[SectorPopulation, Tag("uniform_sector")]],
                       Discriminator("kind")]


class TargetsSpec(ConfigModel):
    """Point targets (fish, squid): explicit points and random populations; and mesh targets
    whose echo comes from their geometry (calibration spheres, rocks, bodies)."""

    points: tuple[PointTarget, ...] = ()
    populations: tuple[Population, ...] = ()
    meshes: tuple[MeshTargetSpec, ...] = ()
