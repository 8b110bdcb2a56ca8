"""The ``sonar`` section of a scene file: the ABACUS preset or explicit arrays, and the pose."""
from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from acoustics.scene.meshes_spec import Bounded, Direction3, Position3
from acoustics.scene.motion_spec import PlatformMotionSpec
from acoustics.sonar import preset
from acoustics.sonar.arrays import ElementArray
from processing.base.config import AngleDeg, ConfigModel, Count, PositiveCount, Real

#: a position (m) on the sonar's mount, within ±100 m of its origin
_MountCoordinate = Bounded(-100.0, 100.0)
_MountPosition = tuple[_MountCoordinate, _MountCoordinate, _MountCoordinate]
#: the size (m) of an element or an element pitch: 10 µm to 10 m
_ElementSize = Bounded(1e-5, 10.0, positive=True)
#: an offset (m) of the preset's geometry, within ±10 m
_Offset = Bounded(-10.0, 10.0)

__all__ = ["PoseSpec", "ElementSpec", "LineSpec", "ArraySpec", "ReceiverSpec", "PresetGeometry",
           "LevelsSpec", "SonarSpec"]


class PoseSpec(ConfigModel):
    """Where the sonar is and where it looks, in the world frame (x forward, y starboard,
    z down). The default looks straight down from the surface with the receiver axis
    (azimuth) athwartships to starboard, as a hull-mounted counting sonar."""

    position_m: Position3 = (0.0, 0.0, 0.0)
    """World position (m) of the sonar-frame origin (the transmitter's phase centre)."""
    boresight: Direction3 = (0.0, 0.0, 1.0)
    """World direction of the boresight +z_s (normalised on load)."""
    receiver_axis: Direction3 = (0.0, 1.0, 0.0)
    """World direction of +x_s, along the receiver subarrays (positive azimuth)."""

    @model_validator(mode="after")
    def _axes(self):
        z, x = np.asarray(self.boresight), np.asarray(self.receiver_axis)
        if np.linalg.norm(z) == 0 or np.linalg.norm(x) == 0:
            raise ValueError("boresight and receiver_axis must be non-zero vectors")
        cos = abs(float(z @ x)) / (np.linalg.norm(z) * np.linalg.norm(x))
        if cos > 1e-6:
            raise ValueError(f"boresight and receiver_axis must be perpendicular "
                             f"(they are {math.degrees(math.acos(min(cos, 1.0))):.4g}° apart)")
        return self


class ElementSpec(ConfigModel):
    """One rectangular piston element, facing +z_s."""

    center_m: _MountPosition
    """Centre (m) in the sonar frame."""
    width_m: _ElementSize
    """Size (m) along the element's local x."""
    height_m: _ElementSize
    """Size (m) along the element's local y."""
    rotation: AngleDeg(-360, 360) = Field(0.0, alias="rotation_deg")
    """In-plane rotation (deg) of local x from +x towards +y."""
    weight: Real = Field(1.0, ge=-1e3, le=1e3)
    """Amplitude weight."""


class LineSpec(ConfigModel):
    """A regular line of identical elements (a compact way to write an array)."""

    count: PositiveCount = Field(le=4096)
    """Elements in the line (at most 4096: ABACUS has 16; every element is a channel)."""
    pitch_m: _ElementSize
    axis: Literal["x", "y"]
    """Direction of the line in the sonar frame."""
    width_m: _ElementSize
    height_m: _ElementSize
    center_m: _MountPosition = (0.0, 0.0, 0.0)
    rotation: AngleDeg(-360, 360) = Field(0.0, alias="rotation_deg")
    stagger_m: _Offset = 0.0
    """Alternate ±offset (m) across the line, in the array plane (first element +)."""


class ArraySpec(ConfigModel):
    """An explicit array: either ``elements`` or ``line``."""

    elements: tuple[ElementSpec, ...] | None = None
    line: LineSpec | None = None

    @model_validator(mode="after")
    def _one_form(self):
        if (self.elements is None) == (self.line is None):
            raise ValueError("give exactly one of 'elements' (a list) or 'line'")
        if self.elements is not None and len(self.elements) == 0:
            raise ValueError("elements is empty; an array needs at least one element")
        return self

    def build(self, name: str) -> ElementArray:
        if self.line is not None:
            ln = self.line
            s = (np.arange(ln.count) - (ln.count - 1) / 2) * ln.pitch_m
            alt = ln.stagger_m * np.where(np.arange(ln.count) % 2 == 0, 1.0, -1.0)
            along = np.array([1.0, 0, 0]) if ln.axis == "x" else np.array([0, 1.0, 0])
            across = np.array([0, 1.0, 0]) if ln.axis == "x" else np.array([1.0, 0, 0])
            c = np.asarray(ln.center_m) + s[:, None] * along + alt[:, None] * across
            return ElementArray(c, ln.width_m, ln.height_m, ln.rotation, 1.0, name)
        e = self.elements
        return ElementArray([x.center_m for x in e], [x.width_m for x in e],
                                    [x.height_m for x in e], [x.rotation for x in e],
                                    [x.weight for x in e], name)


class ReceiverSpec(ConfigModel):
    """Explicit receiver subarrays and the recorded channels."""

    A: ArraySpec
    B: ArraySpec | None = None
    channels_A: tuple[Count, ...] | None = None
    """Recorded elements of A (indices); default all."""
    channels_B: tuple[Count, ...] | None = None
    """Recorded elements of B (indices); default all."""

    @model_validator(mode="after")
    def _channels_exist(self):
        for name in ("A", "B"):
            arr, chosen = getattr(self, name), getattr(self, f"channels_{name}")
            if chosen is None:
                continue
            if arr is None:
                raise ValueError(f"channels_{name} given but there is no subarray {name}")
            n = len(arr.elements) if arr.elements is not None else arr.line.count
            bad = [i for i in chosen if i >= n]
            if bad:
                raise ValueError(f"channels_{name} lists element(s) {bad}; subarray {name} has "
                                 f"{n} elements (indices 0..{n - 1})")
            if len(set(chosen)) != len(chosen):
                raise ValueError(f"channels_{name} lists an element twice")
        return self


class PresetGeometry(ConfigModel):
    """Dimensions the ABACUS preset leaves adjustable (defaults depend on ``variant``;
    docs/arrays.md explains each choice)."""

    transmitter_stagger_m: _Offset
    """Transmitter elements shifted alternately ±this along x (abacus 0.0015, generic 0)."""
    transmitter_rotated_end_elements: Count = Field(le=8)
    """Elements rotated 90° at each end of the transmitter (abacus 3, generic 0)."""
    receiver_stagger_m: _Offset
    """Receiver elements shifted alternately ±this along y (abacus 0.002, generic 0)."""
    subarray_b_offset_m: _Offset
    """Shift of subarray B relative to A along x (abacus 0.0075 = d/2, generic 0)."""
    baseline_m: _ElementSize = preset.BASELINE_M
    """Separation of subarrays A and B along y."""


def _preset_defaults(variant: str) -> dict:
    abacus = variant != "generic"
    return {"transmitter_stagger_m": preset.TX_STAGGER_M if abacus else 0.0,
            "transmitter_rotated_end_elements": 3 if abacus else 0,
            "receiver_stagger_m": preset.RX_STAGGER_M if abacus else 0.0,
            "subarray_b_offset_m": preset.SUBARRAY_B_OFFSET_M if abacus else 0.0,
            "baseline_m": preset.BASELINE_M}


class LevelsSpec(ConfigModel):
    """Physical levels (acoustics/sonar/levels.py): with them ``sampling.adc.scale_counts`` is
    derived (a value given there is replaced) and ``noise.model: sea`` can give the noise."""

    source_level_db: float = Field(210.0, ge=150.0, le=250.0)
    """SL: on-axis source level of the whole transmitter (dB re 1 µPa at 1 m)."""
    receive_sensitivity_db: float = Field(-180.0, ge=-240.0, le=-120.0)
    """M: receiving sensitivity of one element (dB re 1 V/µPa)."""
    receiver_gain_db: float = Field(40.0, ge=-20.0, le=120.0)
    """G: gain from the element to the ADC (dB)."""
    adc_full_scale_v: float = Field(1.0, gt=0.0, le=100.0)
    """Voltage of the ADC's full scale, 2^(bits−1) counts (V)."""


class SonarSpec(ConfigModel):
    """The sonar: the ABACUS preset (``preset: abacus``) or explicit arrays
    (``preset: null`` with ``transmitter`` and ``receiver``)."""

    preset: Literal["abacus"] | None = "abacus"
    variant: Literal["generic", "abacus"] = "abacus"
    """Preset geometry: generic straight lines or the ABACUS layout (stagger, rotation)."""
    preset_geometry: PresetGeometry | None = None
    """Preset dimensions; filled from ``variant`` where not given."""
    transmitter: ArraySpec | None = None
    receiver: ReceiverSpec | None = None
    mode: Literal["interferometric", "normal", "combined"] = "interferometric"
    """interferometric: middle 8 of A and B, two images; normal: 16 of A; combined:
    8 + 8 as one image."""
    pose: PoseSpec = PoseSpec()
    levels: LevelsSpec | None = None
    """Physical source level, sensitivity and gain; none: the thesis' units (k counts per unit)."""
    motion: PlatformMotionSpec | None = None
    """The platform's attitude and heave per ping (roll, pitch, yaw, heave); none: it is still."""

    @model_validator(mode="before")
    @classmethod
    def _fill_preset(cls, data):
        if isinstance(data, dict) and data.get("preset", "abacus") == "abacus":
            variant = data.get("variant", "abacus")
            geo = data.get("preset_geometry")
            if geo is None or isinstance(geo, dict):
                filled = _preset_defaults(variant if isinstance(variant, str) else "abacus")
                filled.update(geo or {})
                data = {**data, "preset_geometry": filled}
        return data

    @model_validator(mode="after")
    def _consistent(self):
        if self.preset is not None:
            if self.transmitter is not None or self.receiver is not None:
                raise ValueError("preset 'abacus' builds the arrays: remove 'transmitter' and "
                                 "'receiver', or set 'preset: null' to give them explicitly")
        else:
            if self.transmitter is None or self.receiver is None:
                raise ValueError("with 'preset: null' both 'transmitter' and 'receiver' are "
                                 "required")
            if self.preset_geometry is not None:
                raise ValueError("'preset_geometry' applies to the preset only")
            if self.mode in ("interferometric", "combined") and self.receiver.B is None:
                raise ValueError(f"mode '{self.mode}' needs two subarrays: add receiver.B, or "
                                 "use mode 'normal'")
        return self
