"""The scene file's schema: the root :class:`Scene` and its small sections.

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
from typing import Literal

import numpy as np
from pydantic import Field, PrivateAttr, model_validator

from acoustics.medium import francois_garrison_db_per_m, mackenzie_sound_speed_m_s
from acoustics.scene.meshes_spec import Bounded, BoundarySpec, ReverberationSpec, SpecularSpec
from acoustics.scene.sonar_spec import SonarSpec
from acoustics.scene.targets_spec import TargetsSpec
from acoustics.sonar import preset
from processing.base.config import (ConfigError, ConfigModel, Count, NonNegativeReal, PositiveCount,
                               PositiveReal, Real, dump_yaml, parse_yaml, validate_file)

__all__ = ["SCHEMA_VERSION", "Scene", "SignalSpec", "AdcSpec", "SamplingSpec", "MediumSpec",
           "NoiseSpec", "PingsSpec", "EffectsSpec", "ArrivalsSpec", "MAX_BOUNCES", "json_schema", "json_schema_text"]

SCHEMA_VERSION = 1


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)



# ------------------------------------------------------------- signal, sampling


class SignalSpec(ConfigModel):
    """The transmit pulse (thesis eq. 2.24–2.27, Table 3.1)."""

    kind: Literal["lfm"] = "lfm"
    """Linear frequency modulation from f0 - B/2 to f0 + B/2 (``sweep: down`` reverses)."""
    center_frequency_hz: PositiveReal = Field(preset.CENTER_FREQUENCY_HZ, le=10e6)
    """Carrier f0 (Hz), at most 10 MHz (sonar frequencies)."""
    bandwidth_hz: NonNegativeReal = Field(preset.BANDWIDTH_HZ, le=10e6)
    """Swept bandwidth B (Hz); 0 gives a CW pulse."""
    duration_s: PositiveReal = Field(preset.PULSE_DURATION_S, le=1.0)
    taper: Literal["sqrt_hann", "hann", "hamming", "tukey", "rectangular"] = "sqrt_hann"
    """Amplitude taper; the thesis' square root of a Hann window (eq. 4.20) by default."""
    sweep: Literal["up", "down"] = "up"


class AdcSpec(ConfigModel):
    """From pressure to ADC counts (thesis §3.6)."""

    scale_counts: PositiveReal = Field(preset.ADC_SCALE_COUNTS, le=1e12)
    """k: counts per unit of pressure, where a transmit element driven at unit amplitude gives
    pressure 1 at 1 m on its axis (the thesis' k maps transmitter volts to ADC counts)."""
    quantize: bool = False
    """Round to integers and clip to the signed range of ``bits`` (per I and Q)."""
    bits: PositiveCount = Field(preset.ADC_BITS, le=32)


class SamplingSpec(ConfigModel):
    """Complex baseband sampling (Table 3.4). t = 0 is the start of transmission."""

    rate_hz: Bounded(100.0, 100e6, positive=True) = preset.SAMPLE_RATE_HZ
    samples: PositiveCount = Field(preset.SAMPLES_PER_PING, le=2**22)
    time_offset_s: NonNegativeReal = Field(0.0, le=100.0)
    """Time (s) of sample 0 after the start of transmission."""
    receiver_bandwidth_hz: PositiveReal | None = Field(None, le=100e6)
    """Receiver (anti-alias) band, centred on the carrier; default rate_hz / 2, the widest
    band real bandpass sampling at rate_hz allows."""
    adc: AdcSpec = AdcSpec()

    @model_validator(mode="before")
    @classmethod
    def _fill_band(cls, data):
        if isinstance(data, dict) and data.get("receiver_bandwidth_hz") is None:
            rate = data.get("rate_hz", preset.SAMPLE_RATE_HZ)
            # only from a rate the schema accepts: a refused rate is named once, not again
            # through the values derived from it
            if isinstance(rate, (int, float)) and not isinstance(rate, bool) and 0 < rate <= 100e6:
                data = {**data, "receiver_bandwidth_hz": float(rate) / 2}
        return data


class MediumSpec(ConfigModel):
    """Homogeneous water. Sound speed given, or by Mackenzie (1981) when null; absorption
    given (dB/m), or by Francois & Garrison (1982) at the carrier when null."""

    sound_speed_m_s: PositiveReal | None = Field(None, ge=1300.0, le=1800.0)
    """c (m/s); null (the default): Mackenzie (1981) from temperature, salinity and depth, so the
    speed follows the water as the absorption does. The thesis' scenes give 1530 explicitly."""
    absorption_db_per_m: NonNegativeReal | None = Field(None, le=100.0)
    temperature_c: Real = Field(10.0, ge=-2.0, le=40.0)
    salinity_psu: Real = Field(35.0, ge=0.0, le=45.0)
    depth_m: NonNegativeReal = Field(20.0, le=12000.0)
    """Depth (m) at which absorption is evaluated."""
    ph: Real = Field(8.0, ge=6.0, le=9.5)


class NoiseSpec(ConfigModel):
    """Receiver and ambient noise: complex white Gaussian, band-limited (thesis §2.4.2)."""

    enabled: bool = False
    model: Literal["counts", "sea"] = "counts"
    """counts: σ as given; sea: the sea's thermal noise and the receiver's own from
    ``sonar.levels`` (acoustics/sonar/levels.py), σ derived (a value given is replaced)."""
    system_noise_nv_per_sqrt_hz: NonNegativeReal = Field(1.0, le=1e6)
    """Receiver input noise density (nV/√Hz), for model: sea."""
    sigma_counts: NonNegativeReal = Field(preset.NOISE_SIGMA_COUNTS, le=1e12)
    """Standard deviation (ADC counts) of each quadrature component (I and Q) of a
    channel, after band-limiting; the thesis' 126.68 by default."""
    bandwidth_hz: PositiveReal | None = Field(None, le=100e6)
    """Noise band centred on the carrier; default the receiver bandwidth."""


# ------------------------------------------------------------------ the rest


class PingsSpec(ConfigModel):
    """Which pings a run computes (each ping is seeded by (seed, ping index))."""

    count: PositiveCount = Field(1, le=10_000_000)
    first: Count = Field(0, le=1_000_000_000)
    """Index of the first ping; pings first .. first + count - 1."""
    interval_s: PositiveReal = Field(preset.PING_INTERVAL_S, le=86400.0)
    """Ping interval (s); ABACUS runs at 1 Hz."""
    start_time: str = "2000-01-01T00:00:00"
    """Time of ping 0 (ISO 8601, UTC); ping p is at start_time + p x interval_s."""

    @model_validator(mode="after")
    def _time(self):
        try:
            start = np.datetime64(self.start_time, "ns")
        except (ValueError, OverflowError):
            raise ValueError("start_time must be an ISO 8601 time such as "
                             "2000-01-01T00:00:00") from None
        if np.isnat(start) or not np.datetime64("1900-01-01") <= start <= np.datetime64("2200-01-01"):
            raise ValueError("start_time must lie between 1900 and 2200")
        last = (self.first + self.count) * self.interval_s
        if last > 50 * 365.25 * 86400:
            raise ValueError(f"the last ping would come {last / 3.15576e7:.3g} years after "
                             f"start_time: at most 50 years (first + count) x interval_s")
        return self


#: the most specular bounces per leg a scene may ask for (planar image sources grow as the
#: number of boundaries to this power)
MAX_BOUNCES = 4


class ArrivalsSpec(ConfigModel):
    """Per-arrival ground truth: one row per path of every ping (docs/dataset.md, "Arrivals")."""

    enabled: bool = False
    """Record every arrival (``abacus simulate --arrivals`` sets it)."""
    floor_db: Real | None = Field(-80.0, ge=-400.0, le=0.0)
    """Keep arrivals no more than this far (dB) below the ping's strongest; null keeps all."""


class FloorTilesSpec(ConfigModel):
    """A generated floor (``rough_floor``) streamed in tiles through the ray caster and the
    specular search, the built tiles' memory bounded (acoustics/paths/tiles.py;
    docs/scenes.md, "Large floors")."""

    enabled: bool = False
    """Stream every ``rough_floor`` in tiles (false: built whole, at most 4 million vertices)."""
    memory_mb: PositiveReal = Field(2000.0, ge=0.01, le=1e7)
    """Most memory (MB) the built tiles of a floor hold at once, their search blocks
    included; the least recently used are evicted."""
    tile_vertices: PositiveCount = Field(513, ge=3, le=8193)
    """Vertices along a tile's side (a tile holds 2 (n − 1)² facets)."""


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
    max_bounces: Count = Field(0, le=MAX_BOUNCES)
    """Specular bounces per leg, every reflecting boundary (0: none; 1: Tx→boundary→target→Rx,
    Tx→target→boundary→Rx and both). Planar boundaries by image sources, any sequence of them;
    a curved boundary (a wavy sea) by its specular points, alone or between planar bounces
    (docs/scenes.md, "Multipath"). Replaces ``multipath_order`` (still read, with a warning)."""
    specular: SpecularSpec = SpecularSpec()
    reverberation: ReverberationSpec = ReverberationSpec()
    doppler: bool = False
    """Echoes of moving targets (and of any target seen from a moving platform) carry their
    Doppler shift 2 v_r f0 / c (a multipath path: −f0/c times the rate its length changes, a
    moving sea's included): with the LFM pulse's range–Doppler coupling a closing speed of
    0.5 m/s biases the range by 7 cm, 2 m/s by 29 cm (docs/accuracy.md, "within-ping motion")."""
    doppler_method: Literal["bank", "bins"] = "bank"
    """How the fast synthesis shifts echoes: ``bank``, a few replicas at Chebyshev nodes of the
    ping's shifts, interpolated in frequency after the LFM's range–Doppler coupling is taken
    out (each echo spread once); ``bins``, a grid of ``doppler_bin_hz`` (docs/accuracy.md)."""
    doppler_error_db: Bounded(-120.0, -10.0) = -50.0
    """``bank``: the fewest nodes whose worst error over the ping's shifts (re the pulse) is
    below this, an accuracy knob (docs/accuracy.md, "Doppler bank")."""
    doppler_bin_hz: Bounded(0.01, 1000.0, positive=True) = 5.0
    """Doppler grid of the fast synthesis (Hz) with ``doppler_method: bins``, an accuracy knob
    (docs/accuracy.md)."""
    stop_and_hop: bool = True
    """A moving platform hears each echo from the pose it had when it transmitted (the
    stop-and-hop approximation). false: the receive leg starts from the pose at the echo's
    arrival, t_p + 2r/c — a roll rate ω turns the image by ω·2r/c, 0.13° at 25 m in a 5°, 8 s
    roll (docs/accuracy.md, "within-ping motion")."""
    ray_threads: PositiveCount | None = None
    """Threads for ray batches (default: every core)."""
    floor_tiles: FloorTilesSpec = FloorTilesSpec()
    arrivals: ArrivalsSpec = ArrivalsSpec()
    """Per-arrival ground truth (off: the run pays nothing for it)."""

    @model_validator(mode="before")
    @classmethod
    def _old_bounce_key(cls, data):
        """``multipath_order`` (abacus ≤ issue 30) is read as ``max_bounces``."""
        if isinstance(data, dict) and "multipath_order" in data:
            data = dict(data)
            old = data.pop("multipath_order")
            if "max_bounces" in data:
                raise ValueError("multipath_order and max_bounces both given: "
                                 "keep max_bounces (multipath_order is its old name)")
            if isinstance(old, bool) or not isinstance(old, int) or not 0 <= old <= MAX_BOUNCES:
                # one line, not a deprecation warning and then an error about the new key
                raise ValueError(f"multipath_order (now max_bounces) must be an integer from 0 "
                                 f"to {MAX_BOUNCES}, got {old!r}")
            warnings.warn("effects.multipath_order is deprecated: read as effects.max_bounces "
                          "(the same count of bounces per leg, now for every boundary)",
                          FutureWarning, stacklevel=2)
            data["max_bounces"] = old
        return data

    @property
    def multipath_order(self) -> int:
        """The old name of :attr:`max_bounces` (read-only)."""
        return self.max_bounces


class Scene(ConfigModel):
    """A complete scene. Build one with :func:`load_scene`."""

    schema_version: Literal[1] = 1
    name: str = Field(min_length=1)
    description: str = ""
    seed: Count = Field(0, le=2**63 - 1)
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
    processing: dict = Field(default_factory=dict)
    """The processing block of the run file, as written: the forward model does not read it
    (the application validates it into :class:`processing.settings.ProcessingSettings`, and
    processing reads it back from a run's /Provenance); only the image's range limits, which
    bound the ground truth's counting volume (:func:`processing.base.counting_volume.image_range_of`)."""

    _source_path: Path | None = PrivateAttr(default=None)
    _resolved_text: str | None = PrivateAttr(default=None)
    _physics_notes: tuple = PrivateAttr(default=())

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
        f0 = sig.get("center_frequency_hz", preset.CENTER_FREQUENCY_HZ)
        if all(_is_num(v) for v in (t, s, d, ph, f0)) and f0 > 0 and s >= 0 and d >= 0:
            if med.get("sound_speed_m_s") is None:
                med["sound_speed_m_s"] = round(float(mackenzie_sound_speed_m_s(t, s, d)), 6)
            if med.get("absorption_db_per_m") is None:
                # F&G with its own sound-speed fit, as the formula was calibrated
                alpha = francois_garrison_db_per_m(f0, t, s, d, ph)
                med["absorption_db_per_m"] = float(f"{float(alpha):.6g}")
        if noise.get("bandwidth_hz") is None:
            band, rate = samp.get("receiver_bandwidth_hz"), samp.get("rate_hz", preset.SAMPLE_RATE_HZ)
            if band is None and _is_num(rate) and 0 < rate <= 100e6:
                band = rate / 2
            if _is_num(band):
                noise["bandwidth_hz"] = float(band)
        return {**data, "medium": med, "noise": noise}

    @model_validator(mode="after")
    def _physical_levels(self):
        """With ``sonar.levels`` the ADC scale, and with ``noise.model: sea`` the noise, follow
        from the physics (acoustics/sonar/levels.py)."""
        lv = self.sonar.levels
        if lv is None:
            if self.noise.model == "sea":
                raise ValueError("noise.model 'sea' needs sonar.levels (source level, sensitivity, "
                                 "gain) to put the sea's noise into counts")
            return self
        from acoustics.sonar import levels as lev
        bits = self.sampling.adc.bits
        k = lev.counts_per_unit(lv, weight_sum=lev.transmit_weight_sum(self.sonar), bits=bits)
        adc = self.sampling.adc.model_copy(update={"scale_counts": float(f"{k:.9g}")})
        object.__setattr__(self, "sampling", self.sampling.model_copy(update={"adc": adc}))
        if self.noise.model == "sea":
            sigma = lev.sea_noise_sigma_counts(
                lv, frequency_hz=self.signal.center_frequency_hz, wavelength_m=self.wavelength_m,
                element_m=_receive_element_m(self), band_hz=self.noise.bandwidth_hz, bits=bits,
                system_noise_v_per_sqrt_hz=self.noise.system_noise_nv_per_sqrt_hz * 1e-9)
            object.__setattr__(self, "noise", self.noise.model_copy(
                update={"sigma_counts": float(f"{sigma:.9g}")}))
        return self

    @model_validator(mode="after")
    def _band_fits(self):
        """Numbers that break the simulation, not just the physics: the pulse must fit the
        complex-baseband band, and its lowest frequency must stay above zero."""
        b, fs, f0 = self.signal.bandwidth_hz, self.sampling.rate_hz, self.signal.center_frequency_hz
        if b > fs:
            raise ValueError(f"signal.bandwidth_hz {b:g} Hz exceeds sampling.rate_hz {fs:g} Hz: "
                             f"complex sampling at {fs:g} Hz holds at most {fs:g} Hz of band")
        if f0 <= b / 2:
            raise ValueError(f"signal.center_frequency_hz {f0:g} Hz must exceed half the bandwidth "
                             f"({b / 2:g} Hz): the sweep would pass through 0 Hz")
        return self

    # ------------------------------------------------------------------ helpers
    @classmethod
    def validated(cls, data, *, file, marks=None, source_path=None) -> "Scene":
        """Validate scene data (a dict as YAML gives it).

        Parameters
        ----------
        data : dict
        file : str or Path
            Names the data in messages.
        marks : dict, optional
            Line number per key path (from :func:`processing.base.config.read_yaml`).
        source_path : Path, optional
            The file the scene belongs to: mesh paths resolve relative to its folder.

        Raises
        ------
        SceneError
            Every problem at once, each with file, line, key path and what is accepted.
        """
        from acoustics.scene.checks import physical_problems
        from acoustics.scene.errors import SceneError
        marks = {} if marks is None else marks
        try:
            scene = validate_file(cls, data, file=file, marks=marks)
        except ConfigError as exc:
            raise SceneError(str(exc), exc.problems) from None
        scene._source_path = None if source_path is None else Path(source_path)
        notes: list = []
        problems = physical_problems(scene, notes=notes)
        scene._physics_notes = tuple(notes)
        from acoustics.scene.errors import raise_problems
        raise_problems(problems, file=file, marks=marks)
        return scene

    def with_updates(self, updates: dict, *, what: str = "updates") -> "Scene":
        """A new scene with ``updates`` applied and validated again (the source path is kept).

        Parameters
        ----------
        updates : dict
            ``{dotted key path: value}`` in the file's own keys and units, e.g.
            ``{"noise.sigma_counts": 100, "targets.populations[0].count": 20,
            "processing.detect.pfa_image": 1e-6}``.
        what : str
            Names the change in error messages (e.g. ``"--sweep noise.sigma_counts=..."``).

        Raises
        ------
        SceneError
            A key that is not in the scene, or a value the schema refuses.
        """
        from acoustics.scene.errors import SceneError
        data, _ = parse_yaml(self.resolved_text(), source=f"{self.source_path or '<scene>'} (resolved)")
        for path, value in updates.items():
            keys = _split_key_path(path)
            node = data
            for k in keys[:-1]:
                try:
                    node = node[k]
                except (KeyError, IndexError, TypeError):
                    raise SceneError(f"{what}: {path!r} is not a key of the scene (at {k!r}); "
                                     f"see `abacus scene show` for the keys") from None
            if isinstance(node, dict) and keys[-1] not in node:
                raise SceneError(f"{what}: {path!r} is not a key of the scene (no {keys[-1]!r}); "
                                 f"see `abacus scene show` for the keys")
            try:
                node[keys[-1]] = value
            except (IndexError, TypeError):
                raise SceneError(f"{what}: {path!r} is not a key of the scene") from None
        return Scene.validated(data, file=f"{self.source_path or '<scene>'} ({what})",
                               source_path=self.source_path)

    @property
    def physics_notes(self) -> tuple:
        """(message, key path) pairs of what the physical checks could not settle when the scene
        was validated (e.g. a run too long for the per-ping check under a moving sea):
        :func:`acoustics.scene.checks.cross_check` warns of them."""
        return self._physics_notes

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


def _receive_element_m(scene) -> tuple:
    """(width, height) of a receive element (m): the preset's, or subarray A's first."""
    if scene.sonar.preset == "abacus":
        return preset.RX_ELEMENT_M
    a = scene.sonar.receiver.A
    if a.line is not None:
        return (a.line.width_m, a.line.height_m)
    return (a.elements[0].width_m, a.elements[0].height_m)


def _split_key_path(path: str) -> list:
    """``"targets.populations[0].count"`` → ``["targets", "populations", 0, "count"]``."""
    out = []
    for part in path.split("."):
        while "[" in part:
            head, rest = part.split("[", 1)
            if head:
                out.append(head)
            idx, part = rest.split("]", 1)
            out.append(int(idx))
        if part:
            out.append(part)
    return out


def json_schema() -> dict:
    """JSON Schema of the scene file (aliases, i.e. the keys a file uses), with each key's
    description (its docstring: made in a process that reads them, processing.base.config.FIELD_DOCS)."""
    from processing.base.config import FIELD_DOCS
    if not FIELD_DOCS:
        import os
        import subprocess
        import sys
        done = subprocess.run([sys.executable, "-c", "import json, acoustics.scene as s; "
                               "print(json.dumps(s.json_schema()))"],
                              env={**os.environ, "ABACUS_FIELD_DOCS": "1"}, capture_output=True,
                              text=True, check=True)
        return json.loads(done.stdout)
    schema = Scene.model_json_schema(by_alias=True, mode="validation")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "abacus scene file"
    return schema


def json_schema_text() -> str:
    return json.dumps(json_schema(), indent=2, sort_keys=False) + "\n"
