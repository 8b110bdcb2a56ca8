"""The ``targets`` section of a scene file: point targets, populations and mesh targets."""
from __future__ import annotations

import math
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import Discriminator, Field, Tag, model_validator

from acoustics.scene.meshes_spec import (MAX_EXTENT_M, Bounded, Coordinate, MeshTargetSpec, Position3,
                                         Size)
from acoustics.scene.motion_spec import SwimSpec
from processing.base.config import (AngleDeg, AngleRangeDeg, ConfigModel, Count, NonNegativeReal,
                               PositiveReal, Real)

__all__ = ["UnitTS", "FixedTS", "RayleighTS", "SwimbladderTS", "Backscatter", "PointTarget", "CuboidPopulation",
           "SectorPopulation", "SchoolPopulation", "Population", "TargetsSpec", "Interval"]

Interval = tuple[Coordinate, Coordinate]
#: a velocity component (m/s), within ±100 m/s
Speed = Bounded(-100.0, 100.0)


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
    scale_m: Bounded(1e-6, 100.0, positive=True) = 0.5
    """Rayleigh scale (m); the untruncated mean is scale·√(π/2)."""
    lo_m: NonNegativeReal = Field(0.25, le=1000.0)
    """At most 6 x scale_m: beyond it the law holds less than 1e-7 of its draws."""
    hi_m: PositiveReal = Field(1.25, le=1000.0)

    @model_validator(mode="after")
    def _bounds(self):
        if not self.lo_m < self.hi_m:
            raise ValueError("lo_m must be below hi_m")
        if self.lo_m > 6 * self.scale_m:
            # F(lo) = 1 - exp(-lo²/2s²) rounds to 1: the truncated law cannot be drawn
            raise ValueError(f"lo_m {self.lo_m:g} m is more than 6 x scale_m ({6 * self.scale_m:g} m): "
                             f"the Rayleigh law has (almost) nothing there to draw; lower lo_m or "
                             f"raise scale_m")
        return self


class SwimbladderTS(ConfigModel):
    """A fish's echo from its gas-filled swimbladder: a pressure-release prolate spheroid
    scattered by physical optics (acoustics/targets/fish.py), at the incidence angle set by the
    fish's heading, its tilt and where it is in the beam. Typical bladders: a quarter to a third
    of the fish's length, 5–10 times longer than wide; validated for kb ≥ 8 (b ≥ 4.5 mm at
    420 kHz) within 1 dB of the exact modal series up to 45° from broadside (docs/accuracy.md)."""

    model: Literal["swimbladder"] = "swimbladder"
    length_m: PositiveReal = Field(0.05, le=1.0)
    """Bladder length 2a (m)."""
    width_m: PositiveReal = Field(0.008, le=0.5)
    """Bladder diameter 2b (m)."""
    tilt_mean: AngleDeg(-90, 90) = Field(0.0, alias="tilt_mean_deg")
    """Mean tilt of the fish (nose up positive), drawn anew each ping; a swimming fish adds the
    climb angle of its path."""
    tilt_sd: AngleDeg(0, 90) = Field(10.0, alias="tilt_sd_deg")
    """Standard deviation of the tilt (deg); in situ values of 5–20° are common."""
    subdivisions: int = Field(5, ge=3, le=8)
    """Mesh resolution: icosphere subdivisions of the spheroid (20 x 4^n facets), a knob
    (docs/accuracy.md, *swimbladder*)."""
    tilt_step: AngleDeg(0.05, 15) = Field(0.5, alias="tilt_step_deg")
    """Step of the tabulated f(α) over 0–90° (deg), a knob (docs/accuracy.md, *swimbladder*)."""

    @model_validator(mode="after")
    def _prolate(self):
        if not self.width_m < self.length_m:
            raise ValueError("width_m must be below length_m (a prolate spheroid)")
        return self


Backscatter = Annotated[Union[Annotated[UnitTS, Tag("unit")], Annotated[FixedTS, Tag("fixed")],
                              Annotated[RayleighTS, Tag("rayleigh")],
                              Annotated[SwimbladderTS, Tag("swimbladder")]],
                        Discriminator("model")]


class PointTarget(ConfigModel):
    """One point target, in the sonar frame as ⟨r, θ, φ⟩ (the thesis' notation) or by
    Cartesian position in the sonar or world frame."""

    frame: Literal["sonar", "world"] = "sonar"
    range_m: PositiveReal | None = Field(None, le=MAX_EXTENT_M)
    azimuth: AngleDeg(-180, 180) | None = Field(None, alias="azimuth_deg")
    elevation: AngleDeg(-90, 90) | None = Field(None, alias="elevation_deg")
    position_m: Position3 | None = None
    velocity_m_s: tuple[Speed, Speed, Speed] | None = None
    """World-frame velocity (m/s): the target starts where it is at ping 0 and moves in a straight
    line. Without it a sonar-frame target stays put relative to the sonar, a world-frame one in
    the world."""
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
    count: Count | None = Field(None, le=100_000_000)
    density_per_m3: NonNegativeReal | None = Field(None, le=1e6)
    redraw: bool = True
    """Draw new positions every ping (true) or keep one draw for the whole run (false: the
    targets keep their identities; needed for ``swim``)."""
    swim: SwimSpec | None = None
    """The targets swim (see :class:`~acoustics.scene.motion_spec.SwimSpec`)."""
    backscatter: Backscatter = UnitTS()
    random_phase: bool = False
    label: str = ""

    @model_validator(mode="after")
    def _count_or_density(self):
        if (self.count is None) == (self.density_per_m3 is None):
            raise ValueError("give exactly one of count or density_per_m3")
        if self.swim is not None and self.redraw:
            raise ValueError("a swimming population keeps its fish from ping to ping: set "
                             "redraw: false (redraw: true draws new positions every ping)")
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


class SchoolPopulation(_Population):
    """A school: targets uniform inside an ellipsoid of the world frame, at least
    ``nearest_neighbour_m`` apart (a hard core, as fish keep a body length or so between them),
    the ellipsoid's first axis along ``heading_deg`` in the horizontal plane. With ``swim`` the
    school's fish swim (its default heading is the school's)."""

    kind: Literal["school"] = "school"
    center_m: Position3
    """Centre (m), world frame (z is depth)."""
    semi_axes_m: tuple[Size, Size, Size]
    """Semi-axes (m): along the heading, across it (horizontal), vertical."""
    heading: AngleDeg(-360, 360) = Field(0.0, alias="heading_deg")
    nearest_neighbour_m: NonNegativeReal = Field(0.0, le=100.0)
    """Minimum distance between two fish (m); 0: none."""

    @property
    def volume_m3(self) -> float:
        a, b, c = self.semi_axes_m
        return 4.0 / 3.0 * math.pi * a * b * c

    @model_validator(mode="after")
    def _packable(self):
        d = self.nearest_neighbour_m
        n = self.count if self.count is not None else self.density_per_m3 * self.volume_m3
        # random sequential packing of hard spheres jams near 38 % of the volume; beyond ~25 %
        # the rejection sampler would crawl: refuse what cannot be drawn
        fraction = n * (math.pi / 6.0) * d**3 / self.volume_m3
        if d > 0 and fraction > 0.25:
            raise ValueError(f"{n:.4g} fish at least {d:g} m apart fill {fraction:.0%} of the "
                             f"school's volume as hard spheres: at most 25 % can be drawn; lower "
                             f"the count or density, or nearest_neighbour_m")
        return self


Population = Annotated[Union[Annotated[CuboidPopulation, Tag("uniform_cuboid")],
                             Annotated[SectorPopulation, Tag("uniform_sector")],
                             Annotated[SchoolPopulation, Tag("school")]],
                       Discriminator("kind")]


class TargetsSpec(ConfigModel):
    """Point targets (fish, squid): explicit points and random populations; and mesh targets
    whose echo comes from their geometry (calibration spheres, rocks, bodies)."""

    points: tuple[PointTarget, ...] = ()
    populations: tuple[Population, ...] = ()
    meshes: tuple[MeshTargetSpec, ...] = ()
