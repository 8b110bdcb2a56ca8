"""Scene files: the one place a scene is read, validated and resolved.

A scene file is YAML with the sections ``schema_version``, ``name``, ``description``,
``seed``, ``sonar``, ``signal``, ``sampling``, ``medium``, ``noise``, ``targets``,
``boundaries``, ``pings``, ``effects`` and ``processing``. :func:`load_scene` returns a
frozen, validated :class:`Scene` with every default filled in (``abacus scene show``
prints it). Units are SI; angles are written in degrees under ``*_deg`` keys and held in
radians. The JSON Schema of the file is ``scenes/scene.schema.json`` (:func:`json_schema`).
"""
from __future__ import annotations

import hashlib
import json
import math
import warnings
from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import (BeforeValidator, Discriminator, Field, PlainSerializer, PrivateAttr, Tag,
                      model_validator)

from processing.config import (AngleDeg, AngleRangeDeg, ConfigError, ConfigModel, ConfigWarning, Count,
                               NonNegativeReal, PositiveCount, PositiveReal, Real, Vec3,
                               dump_yaml, read_yaml, validate_file)
from processing.settings import ProcessingSettings

from . import arrays as _arrays
from .medium import francois_garrison_db_per_m, mackenzie_sound_speed_m_s
from .scene_meshes import BoundarySpec, MeshTargetSpec, ReverberationSpec

__all__ = ["SCHEMA_VERSION", "Scene", "SceneError", "SceneWarning", "load_scene",
           "scene_from_text", "json_schema"]

SCHEMA_VERSION = 1


class SceneError(ConfigError):
    """A scene file that cannot be used; the message names file, line, key and remedy."""


class SceneWarning(ConfigWarning):
    """Legal but surprising physics in a scene (grating lobes, blind zone, ...)."""


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


Interval = tuple[Real, Real]

# ------------------------------------------------------------------------ sonar


class PoseSpec(ConfigModel):
    """Where the sonar is and where it looks, in the world frame (x forward, y starboard,
    z down). The default looks straight down from the surface with the receiver axis
    (azimuth) athwartships to starboard, as a hull-mounted counting sonar."""

    position_m: Vec3 = (0.0, 0.0, 0.0)
    """World position (m) of the sonar-frame origin (the transmitter's phase centre)."""
    boresight: Vec3 = (0.0, 0.0, 1.0)
    """World direction of the boresight +z_s (normalised on load)."""
    receiver_axis: Vec3 = (0.0, 1.0, 0.0)
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

    center_m: Vec3
    """Centre (m) in the sonar frame."""
    width_m: PositiveReal
    """Size (m) along the element's local x."""
    height_m: PositiveReal
    """Size (m) along the element's local y."""
    rotation: AngleDeg(-360, 360) = Field(0.0, alias="rotation_deg")
    """In-plane rotation (deg) of local x from +x towards +y."""
    weight: Real = 1.0
    """Amplitude weight."""


class LineSpec(ConfigModel):
    """A regular line of identical elements (a compact way to write an array)."""

    count: PositiveCount
    pitch_m: PositiveReal
    axis: Literal["x", "y"]
    """Direction of the line in the sonar frame."""
    width_m: PositiveReal
    height_m: PositiveReal
    center_m: Vec3 = (0.0, 0.0, 0.0)
    rotation: AngleDeg(-360, 360) = Field(0.0, alias="rotation_deg")
    stagger_m: Real = 0.0
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

    def build(self, name: str) -> _arrays.ElementArray:
        if self.line is not None:
            ln = self.line
            s = (np.arange(ln.count) - (ln.count - 1) / 2) * ln.pitch_m
            alt = ln.stagger_m * np.where(np.arange(ln.count) % 2 == 0, 1.0, -1.0)
            along = np.array([1.0, 0, 0]) if ln.axis == "x" else np.array([0, 1.0, 0])
            across = np.array([0, 1.0, 0]) if ln.axis == "x" else np.array([1.0, 0, 0])
            c = np.asarray(ln.center_m) + s[:, None] * along + alt[:, None] * across
            return _arrays.ElementArray(c, ln.width_m, ln.height_m, ln.rotation, 1.0, name)
        e = self.elements
        return _arrays.ElementArray([x.center_m for x in e], [x.width_m for x in e],
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

    transmitter_stagger_m: Real
    """Transmitter elements shifted alternately ±this along x (abacus 0.0015, generic 0)."""
    transmitter_rotated_end_elements: Count = Field(le=8)
    """Elements rotated 90° at each end of the transmitter (abacus 3, generic 0)."""
    receiver_stagger_m: Real
    """Receiver elements shifted alternately ±this along y (abacus 0.002, generic 0)."""
    subarray_b_offset_m: Real
    """Shift of subarray B relative to A along x (abacus 0.0075 = d/2, generic 0)."""
    baseline_m: PositiveReal = _arrays.ABACUS_BASELINE_M
    """Separation of subarrays A and B along y."""


def _preset_defaults(variant: str) -> dict:
    abacus = variant != "generic"
    return {"transmitter_stagger_m": _arrays.ABACUS_TX_STAGGER_M if abacus else 0.0,
            "transmitter_rotated_end_elements": 3 if abacus else 0,
            "receiver_stagger_m": _arrays.ABACUS_RX_STAGGER_M if abacus else 0.0,
            "subarray_b_offset_m": _arrays.ABACUS_SUBARRAY_B_OFFSET_M if abacus else 0.0,
            "baseline_m": _arrays.ABACUS_BASELINE_M}


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


# ------------------------------------------------------------- signal, sampling


class SignalSpec(ConfigModel):
    """The transmit pulse (thesis eq. 2.24–2.27, Table 3.1)."""

    kind: Literal["lfm"] = "lfm"
    """Linear frequency modulation from f0 - B/2 to f0 + B/2 (``sweep: down`` reverses)."""
    center_frequency_hz: PositiveReal = 420_375.0
    bandwidth_hz: NonNegativeReal = 20_000.0
    """Swept bandwidth B (Hz); 0 gives a CW pulse."""
    duration_s: PositiveReal = 0.007
    taper: Literal["sqrt_hann", "hann", "hamming", "tukey", "rectangular"] = "sqrt_hann"
    """Amplitude taper; the thesis' square root of a Hann window (eq. 4.20) by default."""
    sweep: Literal["up", "down"] = "up"


class AdcSpec(ConfigModel):
    """From pressure to ADC counts (thesis §3.6)."""

    scale_counts: PositiveReal = 16384.0
    """k: counts per unit of pressure, where a transmit element driven at unit amplitude gives
    pressure 1 at 1 m on its axis (the thesis' k maps transmitter volts to ADC counts)."""
    quantize: bool = False
    """Round to integers and clip to the signed range of ``bits`` (per I and Q)."""
    bits: PositiveCount = Field(12, le=32)


class SamplingSpec(ConfigModel):
    """Complex baseband sampling (Table 3.4). t = 0 is the start of transmission."""

    rate_hz: PositiveReal = 45_455.0
    samples: PositiveCount = 4096
    time_offset_s: NonNegativeReal = 0.0
    """Time (s) of sample 0 after the start of transmission."""
    receiver_bandwidth_hz: PositiveReal | None = None
    """Receiver (anti-alias) band, centred on the carrier; default rate_hz / 2, the widest
    band real bandpass sampling at rate_hz allows."""
    adc: AdcSpec = AdcSpec()

    @model_validator(mode="before")
    @classmethod
    def _fill_band(cls, data):
        if isinstance(data, dict) and data.get("receiver_bandwidth_hz") is None:
            rate = data.get("rate_hz", 45_455.0)
            if isinstance(rate, (int, float)) and not isinstance(rate, bool) and rate > 0:
                data = {**data, "receiver_bandwidth_hz": float(rate) / 2}
        return data


class MediumSpec(ConfigModel):
    """Homogeneous water. Sound speed given, or by Mackenzie (1981) when null; absorption
    given (dB/m), or by Francois & Garrison (1982) at the carrier when null."""

    sound_speed_m_s: PositiveReal | None = 1530.0
    absorption_db_per_m: NonNegativeReal | None = None
    temperature_c: Real = Field(10.0, ge=-2.0, le=40.0)
    salinity_psu: Real = Field(35.0, ge=0.0, le=45.0)
    depth_m: NonNegativeReal = 20.0
    """Depth (m) at which absorption is evaluated."""
    ph: Real = Field(8.0, ge=6.0, le=9.5)


class NoiseSpec(ConfigModel):
    """Receiver and ambient noise: complex white Gaussian, band-limited (thesis §2.4.2)."""

    enabled: bool = False
    sigma_counts: NonNegativeReal = 126.68
    """Standard deviation (ADC counts) of each quadrature component (I and Q) of a
    channel, after band-limiting; the thesis' 126.68 by default."""
    bandwidth_hz: PositiveReal | None = None
    """Noise band centred on the carrier; default the receiver bandwidth."""


# ---------------------------------------------------------------------- targets


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


# ------------------------------------------------------------------ the rest


class PingsSpec(ConfigModel):
    """Which pings a run computes (each ping is seeded by (seed, ping index))."""

    count: PositiveCount = 1
    first: Count = 0
    """Index of the first ping; pings first .. first + count - 1."""
    interval_s: PositiveReal = 1.0
    """Ping interval (s); ABACUS runs at 1 Hz."""
    start_time: str = "2000-01-01T00:00:00"
    """Time of ping 0 (ISO 8601, UTC); ping p is at start_time + p x interval_s."""

    @model_validator(mode="after")
    def _time(self):
        try:
            np.datetime64(self.start_time, "ns")
        except ValueError:
            raise ValueError("start_time must be an ISO 8601 time such as "
                             "2000-01-01T00:00:00") from None
        return self


class EffectsSpec(ConfigModel):
    """Fidelity settings and switches of the forward model (docs/accuracy.md)."""

    directivity: Literal["far_field", "huygens"] = "far_field"
    """Element directivity: analytic far field, or Huygens sub-pistons (near-field exact)."""
    huygens_subdivisions: tuple[PositiveCount, PositiveCount] = (4, 4)
    """Sub-pistons per element along local x and y (huygens only)."""
    baffle: bool = True
    """Elements do not radiate behind their plane."""
    synthesis: Literal["fast", "exact"] = "fast"
    """Echo synthesis: fractional-delay kernel + FFT convolution, or exact evaluation."""
    kernel_length: PositiveCount = Field(8, ge=2, le=64)
    """Windowed-sinc fractional-delay kernel length in fine-grid samples (fast only)."""
    oversampling: PositiveCount = Field(2, le=16)
    """Fast synthesis runs on a grid this many times finer than the samples (fast only)."""
    spreading: bool = True
    """Spherical spreading 1/r per leg."""
    absorption: bool = True
    """Absorption 10^(-α r/20) per leg."""
    occlusion: bool = True
    """Point targets whose transmit or receive path a mesh blocks give no direct echo (only
    with meshes in the scene)."""
    multipath_order: Count = Field(0, le=3)
    """Specular bounces per leg on planar boundaries (0: none; 1: Tx→boundary→target→Rx,
    Tx→target→boundary→Rx and both)."""
    reverberation: ReverberationSpec = ReverberationSpec()
    ray_threads: PositiveCount | None = None
    """Threads for ray batches (default: every core)."""


class Scene(ConfigModel):
    """A complete scene. Build one with :func:`load_scene`."""

    schema_version: Literal[1] = 1
    name: str = Field(min_length=1)
    description: str = ""
    seed: Count = 0
    """Root of every random draw: ping p draws from (seed, p, stream)."""
    sonar: SonarSpec = SonarSpec()
    signal: SignalSpec = SignalSpec()
    sampling: SamplingSpec = SamplingSpec()
    medium: MediumSpec = MediumSpec()
    noise: NoiseSpec = NoiseSpec()
    targets: TargetsSpec = TargetsSpec()
    boundaries: tuple[BoundarySpec, ...] = ()
    pings: PingsSpec = PingsSpec()
    effects: EffectsSpec = EffectsSpec()
    processing: ProcessingSettings = ProcessingSettings()

    _source_path: Path | None = PrivateAttr(default=None)
    _resolved_text: str | None = PrivateAttr(default=None)

    @model_validator(mode="before")
    @classmethod
    def _resolve_environment(cls, data):
        """Fill values computed from other sections, so that a resolved scene is explicit:
        Mackenzie sound speed, F&G absorption at the carrier, the noise band."""
        if not isinstance(data, dict):
            return data
        sections = {k: data.get(k) if data.get(k) is not None else {}
                    for k in ("medium", "signal", "sampling", "noise")}
        if not all(isinstance(v, dict) for v in sections.values()):
            return data  # field validation will name the culprit
        med, sig, samp, noise = (dict(sections[k]) for k in ("medium", "signal", "sampling", "noise"))
        t, s, d, ph = (med.get(k, dflt) for k, dflt in
                       (("temperature_c", 10.0), ("salinity_psu", 35.0), ("depth_m", 20.0), ("ph", 8.0)))
        f0 = sig.get("center_frequency_hz", 420_375.0)
        if all(_is_num(v) for v in (t, s, d, ph, f0)) and f0 > 0 and s >= 0 and d >= 0:
            if "sound_speed_m_s" in med and med["sound_speed_m_s"] is None:
                med["sound_speed_m_s"] = round(float(mackenzie_sound_speed_m_s(t, s, d)), 6)
            if med.get("absorption_db_per_m") is None:
                # F&G with its own sound-speed fit, as the formula was calibrated
                alpha = francois_garrison_db_per_m(f0, t, s, d, ph)
                med["absorption_db_per_m"] = float(f"{float(alpha):.6g}")
        if noise.get("bandwidth_hz") is None:
            band, rate = samp.get("receiver_bandwidth_hz"), samp.get("rate_hz", 45_455.0)
            if band is None and _is_num(rate):
                band = rate / 2
            if _is_num(band):
                noise["bandwidth_hz"] = float(band)
        return {**data, "medium": med, "noise": noise}

    # ------------------------------------------------------------------ helpers
    @property
    def source_path(self) -> Path | None:
        """The file this scene was read from (None when built from text)."""
        return self._source_path

    def resolve_path(self, path: str) -> Path:
        """A path written in the scene, relative to the scene file's folder."""
        p = Path(path)
        if p.is_absolute() or self._source_path is None:
            return p
        return self._source_path.parent / p

    def model_copy(self, *, update=None, deep: bool = False):
        """A copy (with ``update``); the cached resolved text is not carried over."""
        out = super().model_copy(update=update, deep=deep)
        out._resolved_text = None
        return out

    def resolved_text(self) -> str:
        """The fully resolved scene as YAML, every default filled in (round-trips)."""
        if self._resolved_text is None:  # frozen: compute once (YAML dumping is slow)
            self._resolved_text = dump_yaml(self.model_dump(mode="json", by_alias=True))
        return self._resolved_text

    def sha256(self) -> str:
        """SHA-256 of :meth:`resolved_text` (identifies what a run really used)."""
        return hashlib.sha256(self.resolved_text().encode()).hexdigest()

    @property
    def wavelength_m(self) -> float:
        return self.medium.sound_speed_m_s / self.signal.center_frequency_hz


def json_schema() -> dict:
    """JSON Schema of the scene file (aliases, i.e. the keys a file uses)."""
    schema = Scene.model_json_schema(by_alias=True, mode="validation")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "abacus scene file"
    return schema


def json_schema_text() -> str:
    return json.dumps(json_schema(), indent=2, sort_keys=False) + "\n"


# ------------------------------------------------------------------ loading


def _validate(data, *, file, marks) -> Scene:
    try:
        return validate_file(Scene, data, file=file, marks=marks)
    except ConfigError as exc:
        raise SceneError(str(exc), exc.problems) from None


def load_scene(path: str | Path, *, check: bool = True) -> Scene:
    """Read, validate and resolve a scene file.

    Parameters
    ----------
    path : str or Path
        A YAML scene file. Mesh paths inside it resolve relative to its folder.
    check : bool
        Run the physics cross-checks, which emit :class:`SceneWarning` (never fail).

    Returns
    -------
    Scene
        Frozen; SI units, angles in radians.

    Raises
    ------
    SceneError
        Unreadable file, YAML syntax error, unknown key, wrong type, bad value. The
        message names the file, line, key path, value and what is accepted.
    """
    path = Path(path)
    try:
        data, marks = read_yaml(path)
    except ConfigError as exc:
        raise SceneError(str(exc)) from None
    if data is None:
        raise SceneError(f"{path}: the file is empty; a scene needs at least 'name'")
    scene = _validate(data, file=path, marks=marks)
    scene._source_path = path.resolve()
    _check_files(scene, path, marks)
    if check:
        for message, key in cross_check(scene):
            line = marks.get(tuple(_key_tuple(key)))
            where = f"{path}:{line}" if line else str(path)
            warnings.warn(f"{where}: {key}: {message}", SceneWarning, stacklevel=2)
    return scene


def mesh_files(scene: Scene):
    """(key, path written in the scene) of every file a scene's meshes read."""
    items = [(f"boundaries[{i}]", b) for i, b in enumerate(scene.boundaries)]
    items += [(f"targets.meshes[{i}]", t) for i, t in enumerate(scene.targets.meshes)]
    for key, spec in items:
        file = getattr(spec.mesh, "file", None)
        if file is not None:
            yield f"{key}.mesh.file", file


def _check_files(scene: Scene, path: Path, marks):
    """A missing mesh or height-grid file is a scene error at load, not a surprise mid-run."""
    for key, file in mesh_files(scene):
        target = scene.resolve_path(file)
        if not target.is_file():
            line = marks.get(tuple(_key_tuple(key)))
            where = f"{path}:{line}" if line else str(path)
            raise SceneError(f"{where}: {key}: file {file!r} not found (looked for {target}); "
                             f"paths are relative to the scene file's folder")


def scene_from_text(text: str, *, name: str = "<text>", check: bool = False) -> Scene:
    """Validate a scene given as YAML text (tests, notebooks)."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "scene.yaml"
        p.write_text(text)
        try:
            return load_scene(p, check=check)
        except SceneError as exc:
            raise SceneError(str(exc).replace(str(p), name), exc.problems) from None


def _key_tuple(key: str):
    out = []
    for part in key.replace("]", "").split("."):
        if "[" in part:
            head, *idx = part.split("[")
            out.append(head)
            out.extend(int(i) for i in idx)
        else:
            out.append(part)
    return out


def cross_check(scene: Scene) -> list[tuple[str, str]]:
    """Physics that is legal but surprising: (message, key path) pairs."""
    from .sonar import build_sonar  # local: sonar imports this module's types
    from .targets import point_positions_sonar
    out = []
    lam = scene.wavelength_m
    sonar = build_sonar(scene)
    rx = sonar.receiver
    pitches: dict[float, list[str]] = {}
    for group, idx in rx.image_groups.items():
        x = np.sort(rx.elements.center_m[idx, 0])
        if x.size > 1:
            pitches.setdefault(round(float(np.min(np.diff(x))), 12), []).append(group)
    for pitch, groups in pitches.items():
        if pitch > lam / 2:
            gl = math.degrees(math.asin(min(1.0, lam / pitch)))
            out.append((f"receiver pitch {pitch * 1e3:.4g} mm exceeds λ/2 = {lam / 2 * 1e3:.4g} mm: "
                        f"grating lobes at ±{gl:.2f}° in image{'s' if len(groups) > 1 else ''} "
                        f"{' and '.join(groups)} (ABACUS has them on purpose; scan within "
                        f"±{gl / 2:.2f}°)", "sonar"))
    fs, band = scene.sampling.rate_hz, scene.signal.bandwidth_hz
    if fs < band:
        out.append((f"rate {fs:g} Hz is below the pulse bandwidth {band:g} Hz: even complex "
                    f"sampling aliases the echo", "sampling.rate_hz"))
    elif fs < 2 * band:
        out.append((f"rate {fs:g} Hz is below 2B = {2 * band:g} Hz: the real bandpass-sampled "
                    f"system would alias (this complex-baseband simulation does not)",
                    "sampling.rate_hz"))
    if scene.sampling.receiver_bandwidth_hz < band:
        out.append((f"receiver band {scene.sampling.receiver_bandwidth_hz:g} Hz is narrower than "
                    f"the pulse bandwidth {band:g} Hz", "sampling.receiver_bandwidth_hz"))
    c = scene.medium.sound_speed_m_s
    blind = c * scene.signal.duration_s / 2
    t_end = scene.sampling.time_offset_s + scene.sampling.samples / fs
    r_max = c * (t_end - scene.signal.duration_s) / 2
    r_first = c * scene.sampling.time_offset_s / 2
    for i, t in enumerate(scene.targets.points):
        pos = point_positions_sonar([t], sonar.pose)[0]
        r = float(np.linalg.norm(pos))
        key = f"targets.points[{i}]"
        if r < max(blind, r_first):
            out.append((f"target at {r:.3g} m is inside the blind zone (< {max(blind, r_first):.3g} m "
                        f"while transmitting or before recording starts)", key))
        elif r > r_max:
            out.append((f"target at {r:.3g} m is beyond the last range whose whole echo is "
                        f"recorded ({r_max:.3g} m)", key))
    for i, p in enumerate(scene.targets.populations):
        if isinstance(p, SectorPopulation) and p.range_m[0] < blind:
            out.append((f"population reaches into the blind zone (< {blind:.3g} m)",
                        f"targets.populations[{i}].range_m"))
    return out
