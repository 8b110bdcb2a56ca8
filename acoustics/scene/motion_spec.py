"""Scene-file sections for motion: how fish swim, and how the platform moves.

Motion is sampled at the ping times t_p = p x ``pings.interval_s`` (ping 0 at t = 0): targets
advance between pings, the platform takes a new pose each ping. Within a ping positions hold
(the 7 ms pulse and the 90 ms record move a fish less than a range cell), but the Doppler shift
of a closing speed does move its echo through the LFM's range–Doppler coupling: that is
``effects.doppler`` (docs/accuracy.md, "within-ping motion", has the numbers).

A motion file (``sonar.motion: {kind: file, file: ...}``) is user input, read through the file
gate (:mod:`processing.base.files`) when the scene is loaded — so ``abacus scene check``
reports what ``simulate`` would meet: it lies in the scene's folder (or below), is a regular
UTF-8 text file (a byte-order mark is allowed) of at most 64 MB and 1 000 000 rows (2.8 h at
100 Hz), its first line a header naming ``time_s`` and any of the other columns once each, then
one row of numbers per time, separated by commas. Semicolons, tabs or decimal commas are refused
with a line saying commas are expected (a ``;`` file is ambiguous: its ``0,5`` may be a number
or two). Times increase strictly; values are bounded as the inline series' are, by one rule
(:data:`acoustics.sonar.platform.MOTION_BOUNDS`: angles within ±360°, heave within ±20 m).
Every problem is one line with the file, line and column, never the text found there.
"""
from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from acoustics.sonar.platform import MOTION_BOUNDS, motion_time_problem, motion_value_problem
from processing.base.config import AngleDeg, ConfigModel, NonNegativeReal, PositiveCount, Real

__all__ = ["SwimSpec", "SwellSpec", "MotionSeriesSpec", "PlatformMotionSpec"]


class SwimSpec(ConfigModel):
    """How the targets of a population swim (world frame; their identities persist, so the
    population must keep its draw: ``redraw: false``).

    Each target gets a speed (normal, truncated at 0) and a heading in the horizontal plane
    (von Mises about ``heading_deg`` with the concentration that gives the mean resultant
    length ``polarisation``), then turns by a random walk of ``turn_sd_deg_per_s`` per √s (its
    own, or the population's with ``turn_together``); its depth changes with a speed drawn from
    N(0, ``vertical_sd_m_s``). Fish swim independently otherwise: nothing pulls a school
    together, so a school whose headings spread by δ widens by about v t sin δ. Positions are the exact
    integral of the piecewise-constant velocity over ``substeps`` steps per ping interval.
    """

    speed_m_s: NonNegativeReal = Field(0.5, le=20.0)
    """Mean swimming speed (m/s)."""
    speed_sd_m_s: NonNegativeReal = Field(0.0, le=20.0)
    heading: AngleDeg(-360, 360) = Field(0.0, alias="heading_deg")
    """Mean heading in the world's horizontal plane (deg, from +x towards +y)."""
    polarisation: Real = Field(1.0, ge=0.0, le=1.0)
    """Mean resultant length of the headings: 1 all parallel, 0 uniformly random."""
    turn_sd: AngleDeg(0, 3600) = Field(0.0, alias="turn_sd_deg_per_s")
    """Heading random walk: standard deviation (deg) of the turn over one second."""
    turn_together: bool = False
    """All targets of the population turn by the same increments (a school changing course
    together): the headings' polarisation holds over the run. false: each turns on its own and
    the mean resultant length decays as exp(−σ_turn² t / 2)."""
    vertical_sd_m_s: NonNegativeReal = Field(0.0, le=5.0)
    substeps: PositiveCount = Field(10, le=1000)
    """Integration steps per ping interval (turning changes the heading once per step): an
    accuracy knob (docs/accuracy.md, "Swimming: integration sub-steps"); exact without turning."""


class SwellSpec(ConfigModel):
    """A platform rolling, pitching and heaving in a swell: sinusoids of the given amplitudes
    and periods (phase 0 at ping 0)."""

    roll_amplitude: AngleDeg(0, 45) = Field(0.0, alias="roll_amplitude_deg")
    roll_period_s: float = Field(8.0, gt=0.5, le=600.0)
    pitch_amplitude: AngleDeg(0, 45) = Field(0.0, alias="pitch_amplitude_deg")
    pitch_period_s: float = Field(6.0, gt=0.5, le=600.0)
    heave_amplitude_m: NonNegativeReal = Field(0.0, le=20.0)
    heave_period_s: float = Field(7.0, gt=0.5, le=600.0)


class MotionSeriesSpec(ConfigModel):
    """A measured motion series, interpolated linearly at the ping times (held at its ends).
    Angles in degrees, heave in metres (positive up)."""

    # bounded as a motion file is (acoustics.sonar.platform.MOTION_BOUNDS, the one rule of
    # both): angles within ±360°, heave within ±20 m

    time_s: tuple[Real, ...]
    roll_deg: tuple[Real, ...] | None = None
    pitch_deg: tuple[Real, ...] | None = None
    yaw_deg: tuple[Real, ...] | None = None
    heave_m: tuple[Real, ...] | None = None

    @model_validator(mode="after")
    def _consistent(self):
        n = len(self.time_s)
        problem = motion_time_problem(self.time_s)
        if problem is not None:
            raise ValueError(problem[1])
        for key in MOTION_BOUNDS:
            v = getattr(self, key)
            if v is not None and len(v) != n:
                raise ValueError(f"{key} has {len(v)} values for {n} times")
            for i, x in enumerate(v or ()):
                bad = motion_value_problem(key, x)
                if bad is not None:
                    raise ValueError(f"{key}[{i}]: {bad}")
        return self


class PlatformMotionSpec(ConfigModel):
    """The platform's attitude and heave per ping: a swell model, an inline series, or a CSV
    file (columns ``time_s`` and any of ``roll_deg``, ``pitch_deg``, ``yaw_deg``, ``heave_m``;
    relative to the scene file's folder).

    Conventions (docs/conventions.md): the vessel frame is the world frame at rest (x forward,
    y starboard, z down); roll is about x (starboard down positive), pitch about y (bow up
    positive), yaw about z (clockwise seen from above positive); the attitude rotation is
    R = R_z(yaw) R_y(pitch) R_x(roll) and it turns the sonar's mounting (``sonar.pose``) about
    the vessel's reference point (the world origin); heave lifts everything (world z − heave).
    """

    kind: Literal["swell", "series", "file"]
    swell: SwellSpec | None = None
    series: MotionSeriesSpec | None = None
    file: str | None = None

    @model_validator(mode="after")
    def _one(self):
        given = {"swell": self.swell, "series": self.series, "file": self.file}
        if given[self.kind] is None:
            raise ValueError(f"kind '{self.kind}' needs '{self.kind}'")
        extra = [k for k, v in given.items() if v is not None and k != self.kind]
        if extra:
            raise ValueError(f"kind '{self.kind}' takes only '{self.kind}', not {', '.join(extra)}")
        return self
