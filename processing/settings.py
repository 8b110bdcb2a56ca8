"""Processing settings: the ``processing`` section of a scene file, or a YAML of their own.

Every field has the thesis' value as its default (Tables 6.2, 6.3, 6.5); see
docs/conventions.md for units.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from processing.base.counting_volume import DEFAULT_IMAGE_RANGE_M
from processing.base.config import (AngleDeg, AngleRangeDeg, ConfigModel, Count, NonNegativeReal, PositiveCount, PositiveReal,
                     Real, read_yaml, validate_file)

__all__ = ["ImageSettings", "NoiseSettings", "CfarSettings", "DetectSettings", "CountSettings", "TrackSettings",
           "SingleTargetSettings", "SONAR_NETCDF4_PARAMETERS", "ProcessingSettings", "load_settings", "WINDOWS"]

#: windows accepted by name (scipy.signal.windows), range and spatial
WINDOWS = ("rectangular", "hamming", "hann", "taylor", "blackman")


class ImageSettings(ConfigModel):
    """Pulse compression, interpolation and beamforming (thesis chapter 4)."""

    range_m: tuple[PositiveReal, PositiveReal] | None = DEFAULT_IMAGE_RANGE_M
    """Image range limits (m); null keeps the whole record."""
    range_window: Literal[WINDOWS] = "hamming"
    """Range (frequency-domain) weighting of the matched filter (§4.3)."""
    interpolation: PositiveCount = Field(4, le=64)
    """Band-limited interpolation factor in range; 1 = off (§4.4)."""
    beamformer: Literal["fft", "delay_and_sum", "wideband"] = "fft"
    """fft: zero-padded FFT with phase-centre correction; delay_and_sum: exact narrowband
    phases; wideband: true time delays (the reference)."""
    n_beams: PositiveCount | None = 32
    """Number of beams; null meets the spatial Nyquist rate over the span."""
    azimuth_span: AngleDeg(0, 180, lo_open=True) | None = Field(None, alias="azimuth_span_deg")
    """Full scan span (deg); null = the grating-lobe-free span arcsin(λ/d)."""
    spatial_window: Literal[WINDOWS] = "hamming"
    """Across-array weighting (§4.5.5)."""

    @model_validator(mode="after")
    def _range_order(self):
        if self.range_m is not None and not self.range_m[0] < self.range_m[1]:
            raise ValueError("range_m must be [near, far] with near < far")
        return self


class NoiseSettings(ConfigModel):
    """Where the Rayleigh noise level comes from (thesis §5.2.3)."""

    source: Literal["image", "region", "noise_file"] = "image"
    """image: a robust (median) estimate from the images themselves; region: the cells in
    ``range_m`` x ``azimuth_deg``; noise_file: a noise-only dataset processed the same way."""
    estimator: Literal["median", "ml"] = "median"
    """median: σ = median/√(2 ln 2), robust to sparse targets; ml: maximum likelihood
    σ² = Σx²/2n (exact for pure noise, biased by targets)."""
    per_ping: bool = False
    """Estimate per ping (noise varying with ping) or pooled over all pings (the thesis)."""
    range_m: tuple[PositiveReal, PositiveReal] | None = None
    """Region (source: region)."""
    azimuth: AngleRangeDeg(-90, 90) | None = Field(None, alias="azimuth_deg")
    """Region (source: region)."""
    file: str | None = None
    """Noise-only dataset (source: noise_file). In a run file: relative to the scene file's
    folder and inside it (the file gate, processing/base/files.py); given with ``--settings`` or
    from Python: relative to the working directory, and inside it."""

    @model_validator(mode="after")
    def _region(self):
        if self.source == "region" and self.range_m is None:
            raise ValueError("source 'region' needs range_m (and optionally azimuth_deg)")
        if self.source == "noise_file" and not self.file:
            raise ValueError("source 'noise_file' needs file")
        return self


class CfarSettings(ConfigModel):
    """2-D CFAR on |I|² with guard and training cells around each cell under test."""

    kind: Literal["ca", "os"] = "ca"
    """ca: cell averaging; os: ordered statistic (robust to targets in the training cells)."""
    guard: tuple[Count, Count] = (8, 1)
    """Guard cells each side (range samples of the interpolated image, beams)."""
    training: tuple[PositiveCount, PositiveCount] = (24, 3)
    """Training cells each side beyond the guard cells (range samples, beams)."""
    rank: Real = Field(0.75, gt=0, lt=1)
    """OS-CFAR: the order statistic as a fraction of the training cells."""


class DetectSettings(ConfigModel):
    """Thresholds and peaks (thesis chapter 5)."""

    method: Literal["rayleigh", "fixed", "fraction_of_peak", "cfar"] = "rayleigh"
    """rayleigh: T from the noise level and a false-alarm probability; fixed: T = value;
    fraction_of_peak: T = fraction x the brightest cell of each ping (thesis §6.3); cfar."""
    pfa_image: Real = Field(1e-7, gt=0, lt=1)
    """Probability of any false alarm in the tested cells of one image (thesis: <= 1e-7)."""
    convention: Literal["correct", "thesis"] = "correct"
    """correct: P_cell = 1 − (1 − α)^(1/N) and T = σ√(−2 ln P_cell); thesis: eq. 5.4 and 5.9 as
    printed, P_cell = 1 − α^(1/N) and T = √(−2 μ² (π/2) ln P_cell) (reproduces 9.05e-4, ~656)."""
    value: NonNegativeReal | None = None
    """Fixed threshold for method: fixed, in ``value_units``."""
    value_units: Literal["counts", "noise_mean", "thesis"] = "counts"
    """counts: image units (ADC counts); noise_mean: multiples of the estimated noise mean μ;
    thesis: the thesis' image units, T = value x μ / thesis_noise_mean. The thesis' images are
    not calibrated, so its thresholds (600–2000, §6.3.6) only carry over relative to its noise
    mean; this keeps T/μ as in the thesis."""
    thesis_noise_mean: PositiveReal = 139.8
    """The thesis' noise mean μ in its image units (Table 6.5), for value_units: thesis."""
    fraction: Real = Field(0.15, gt=0, lt=1)
    """For method: fraction_of_peak (0.15 in §6.3, 0.10 in §6.3.3)."""
    noise: NoiseSettings = NoiseSettings()
    cfar: CfarSettings = CfarSettings()
    image_group: str = "A"
    """Image to detect on (A, as the thesis; B; or AB in combined mode)."""
    elevation: Literal["peak", "fit"] = "peak"
    """The interferometric phase of a detection: "peak", arg(I_A I_B*) at its peak cell (the
    reference, the thesis'); "fit", where the echo does not fit one point response and two fit
    it much better (a neighbour within about a cell: glint), the phase, azimuth and range of the
    fitted target nearest the peak (processing/detection/elevation_fit.py; slower: a few fits
    per detection above 30 dB SNR)."""

    @model_validator(mode="after")
    def _fixed(self):
        if self.method == "fixed" and self.value is None:
            raise ValueError("method 'fixed' needs value (a threshold in value_units, default ADC "
                             "counts)")
        return self

    @property
    def needs_noise(self) -> bool:
        """Whether the threshold derives from a noise estimate."""
        return self.method == "rayleigh" or (self.method == "fixed" and self.value_units != "counts")


class CountSettings(ConfigModel):
    """The counting volume (default: the transmitter's 3 dB beam x the image's range limits)
    and the matching of detections to the ground truth."""

    azimuth_halfwidth: AngleDeg(0, 90, lo_open=True) | None = Field(None, alias="azimuth_halfwidth_deg")
    """Default: half the transmitter's 3 dB azimuth width (5.14° for ABACUS)."""
    elevation_halfwidth: AngleDeg(0, 90, lo_open=True) | None = Field(None, alias="elevation_halfwidth_deg")
    """Default: half the transmitter's 3 dB elevation width (0.43°)."""
    range_m: tuple[PositiveReal, PositiveReal] | None = None
    """Default: the image's range limits."""
    gate_cells: PositiveReal = 1.0
    """Matching gate in resolution cells (range 3 dB width, azimuth 3 dB width)."""
    unresolved_cells: PositiveReal = 1.5
    """Two true targets closer than this (in resolution cells) count as sharing a resolution
    cell when one is missed: the Rayleigh limit of a Hamming-weighted aperture is ~1.4 of its
    3 dB width."""
    sidelobe_db: NonNegativeReal = Field(30.0, le=100)
    """A detection more than this (dB) below a stronger detection of its ping, inside that one's
    point-spread response (within 2.5 range cells at any azimuth: azimuth sidelobes and grating
    ghosts; within its beam and the compressed pulse's length: range sidelobes), is that one's
    sidelobe and is not counted (processing/detection/sidelobes.py). 0 counts every detection
    (the reference, the thesis' counting)."""
    ghost_db: NonNegativeReal = Field(6.0, le=100)
    """A detection within 2.5 range cells of a stronger one, at that one's ghost azimuth
    (sin θ ± λ / (2 d) for a staggered receiver subarray of pitch d, ± λ / d otherwise) and no
    more than this (dB) above the ghost level its interferometric elevation predicts
    (|tan(k δ sin φ)| for a stagger ±δ), is its ghost and is not counted. 0: no ghost rule (the
    reference)."""
    coincidence_correction: Literal["none", "poisson"] = "none"
    """Correct the per-ping count for fish sharing a resolution cell (one echo for two;
    processing/detection/coincidence.py): "poisson" adds ``count_corrected`` = the expected
    number of fish behind the count, for fish spread uniformly (D = N e^(−aN), a from the
    resolution cell of ``unresolved_cells`` and the volume), and the density uses it; "none"
    counts echoes (the reference). The default "none" is the evidence of docs/validation.md's
    "Counting against density": at the thesis' density the correction's gain in bias is smaller
    than the noise it adds to each ping; it pays in denser schools."""
    volume_edge: Literal["hard", "soft"] = "hard"
    """How a detection is tested against the counting volume's elevation faces
    (processing/detection/volume_edge.py): "hard" counts it when its located position lies
    inside (the reference, the thesis' counting); "soft" counts it with the probability that its
    fish lies inside given its located elevation and that elevation's Cramér–Rao σ (from its
    SNR, the baseline and the wavelength), and adds ``count_expected``, which the densities
    then use. The default "hard" is the evidence of docs/validation.md's "Counting against
    density": the soft count is the posterior mean, least in squared error, but the per-ping
    nMAE sums absolute errors, for which the hard decision is best; on the development seeds the
    soft edge raised the per-ping nMAE at every density (7.1 % → 9.6 % at the thesis' density)."""
    edge_interference_db: PositiveReal | None = Field(None, le=100)
    """With ``volume_edge: soft``: a signal-to-interference ratio (dB) that caps the SNR behind σ
    (a neighbour's echo, not the noise, limits a strong echo's elevation); null: noise only."""


class TrackSettings(ConfigModel):
    """Tracking detections across pings (processing/tracking/filters.py): filter, gate, confirmation
    and deletion rules, and the distance within which a track scores as a true fish."""

    method: Literal["kalman", "alpha_beta"] = "kalman"
    """Constant-velocity Kalman filter with RTS smoothing, or the thesis' αβ filter (§7)."""
    association: Literal["gnn", "jpda"] = "gnn"
    """Gate-and-assign part (processing/tracking/association.py): global nearest neighbour, or
    the parametric JPDA, which shares a detection falling in several tracks' gates."""
    resolution_cells: NonNegativeReal = Field(1.0, le=10)
    """Resolution gate: a track the assignment left without a detection takes one within this
    many resolution cells (range × azimuth resolution × the fan's elevation width) of its
    prediction, and no new track starts within it of a confirmed track (two fish closer than a
    cell are not told apart; the cell's spread is δ/√12 per axis);
    0 turns it off (processing.tracking.filters.track_detections)."""
    confirm_resolved: bool = True
    """With the resolution gate: a tentative track's hit counts towards confirmation only when
    its detection lies outside the resolution gate of every senior track (confirmed, or with
    more hits, or as many and born first) that took a detection at that ping — the resolution
    gate's rule for births carried through the confirmation window, so that two peaks of one
    merged echo born together (the first pings, before any track is confirmed) confirm one
    track, not two (processing.tracking.filters.track_detections). False: every hit counts."""
    gate_probability: Real = Field(0.99, gt=0.5, lt=1)
    """Chi-square gate (3 degrees of freedom) on the innovation's Mahalanobis distance."""
    split: Literal["none", "fan_crossing"] = "fan_crossing"
    """Track-splitting part (processing/tracking/splitting.py): "fan_crossing" cuts a finished
    track where its detections step back through the fan's thin dimension against the track's
    own motion through it (a second fish entering behind the first, one echo to the gate);
    "none" keeps every track whole."""
    split_probability: Real = Field(0.999, gt=0.5, lt=1)
    """The fan-crossing split's test: the probability whose chi-square quantile the two lines'
    likelihood ratio against one (2 degrees of freedom), each line's motion through the fan and
    the step back (1 degree of freedom each) must exceed."""
    accel_sd_m_s2: PositiveReal = Field(0.05, le=100)
    """Process noise: white acceleration of this spectral density √q (m/s² per √(1/s)). 0.05 suits
    schooling fish cruising nearly straight at body lengths per second; a larger value follows
    sharper turns but lets a track jump to a neighbour (docs/validation.md, "Tracking")."""
    initial_speed_sd_m_s: PositiveReal = Field(0.5, le=100)
    """Velocity spread of a new track (m/s); the αβ gate's allowance for motion."""
    alpha: Real = Field(0.5, gt=0, le=1)
    """αβ position gain."""
    beta: Real = Field(0.2, gt=0, le=2)
    """αβ velocity gain."""
    confirm_hits: PositiveCount = Field(3, le=100)
    """Detections a tentative track needs within its first ``confirm_window`` pings."""
    confirm_window: PositiveCount = Field(4, le=100)
    max_misses: Count = Field(10, le=100)
    """Consecutive pings without a detection after which a track ends (10: a fish hidden for
    2.5 s in a neighbour's echo at 0.25 s pings keeps its track; docs/validation.md, "Tracking")."""
    sidelobe_db: NonNegativeReal = Field(20.0, le=100)
    """Single targets: a detection within 2.5 range cells of one this much stronger (dB), or
    weaker and in its resolution cell, is taken as its range or azimuth sidelobe (or ghost) and
    not tracked; 0 tracks everything. In a dense school the same-cell part drops fish side by
    side with a stronger one; off (0), a strong lone fish's sidelobes form short tracks of
    their own (docs/validation.md, "Tracking")."""
    min_ts_db: Real = Field(-70.0, ge=-200, le=50)
    """TS threshold of single targets (dB re 1 m²): a detection whose beam-compensated TS is
    below it (a multipath echo via the floor, a far range sidelobe) is not tracked; one beyond
    the compensable beam (TS NaN) is kept."""
    interference_db: Real = Field(20.0, ge=0, le=100)
    """Signal-to-interference ratio (dB) capping a detection's effective SNR in its position
    covariance (processing.tracking.filters.measurement_covariance)."""
    score_distance_m: PositiveReal = Field(0.3, le=10)
    """A track's position within this distance of a true fish matches it (scoring)."""

    @model_validator(mode="after")
    def _window(self):
        if self.confirm_window < self.confirm_hits:
            raise ValueError(f"confirm_window ({self.confirm_window}) must be at least "
                             f"confirm_hits ({self.confirm_hits})")
        return self


class SingleTargetSettings(ConfigModel):
    """Single-target detection by the echosounder criteria (Soule et al. 1995, 1997; Ona 1999;
    Simrad EK60/EK80, Echoview): each field is a detection parameter of the SONAR-netCDF4 2.0
    SingleTarget group (``param_<name>`` there; :data:`SONAR_NETCDF4_PARAMETERS`), with its
    meaning. Echo lengths are measured at the −6 dB points of the matched-filter envelope and
    normalised by the nominal (compressed) pulse's, the same measure on the range filter's own
    point response (processing/backscatter/echo_criteria.py, docs/single_targets.md)."""

    ts_threshold_db: Real = Field(-50.0, ge=-200, le=50)
    """param_TS_threshold: minimum compensated TS (dB re 1 m²) of a single target."""
    gain_compensation_db: NonNegativeReal = Field(6.0, le=60)
    """param_gain_compensation: maximum one-way beam compensation (dB): half the two-way
    compensation at the located angles."""
    minimum_echo_duration: PositiveReal = Field(0.9, le=100)
    """param_minimum_echo_duration: minimum −6 dB echo length relative to the nominal pulse's.
    One echo of the compressed pulse has the nominal length within ±3 % at SNR ≥ 35 dB
    (docs/single_targets.md); EK60's CW defaults (0.8–2.5) allow for a CW envelope that a
    matched filter with the known replica does not have."""
    maximum_echo_duration: PositiveReal = Field(1.1, le=100)
    """param_maximum_echo_duration: maximum −6 dB echo length relative to the nominal pulse's."""
    maximum_phase_deviation: NonNegativeReal | None = Field(3.0, alias="maximum_phase_deviation_deg",
                                                           le=180)
    """param_maximum_phase_deviation: maximum standard deviation (deg, electrical) of the phase
    over the samples within the echo's −6 dB points, in either plane (elevation: ψ_AB; azimuth:
    the split-aperture phase of the beam-domain peak), each plane against this limit widened by
    its own noise (``phase_deviation_sigmas``); null: not applied. Noise
    alone gives ≈ 0.5° at SNR 50 dB and up to ≈ 3° at 38 dB, which ``phase_deviation_sigmas``
    allows for."""
    maximum_range_phase_deviation: NonNegativeReal | None = Field(
        1.0, alias="maximum_range_phase_deviation_deg", le=180)
    """Maximum standard deviation (deg) of the echo's own phase along range within its −6 dB
    points (the mean over the subarrays' images): one echo of the matched filter's point
    response has one phase across it (≤ 0.1° for a point target at any SNR), two echoes closer
    than the range resolution turn it by ≈ Im(a₂/(a₁+a₂)) δ p′/p, first order in their
    separation δ where the envelope broadens at second order (rule
    ``maximum_range_phase_deviation``; no SONAR-netCDF4 parameter); null: not applied."""
    maximum_radial_speed_m_s: NonNegativeReal = Field(1.0, le=100)
    """The fastest radial speed (m/s, target relative to the sonar) a single target may have:
    a moving echo's phase runs along range (the pulse's range–Doppler coupling: ≈ 2° per m/s
    for the 20 kHz LFM pulse at 420 kHz; far more for a long CW pulse), so the range phase
    limit is widened in quadrature by what one echo at this speed shows, computed from the
    record's replica (processing/backscatter/echo_criteria.py,
    ``moving_echo_range_phase_deg``). 0: still targets only (a calibration sphere)."""
    phase_deviation_sigmas: NonNegativeReal = Field(2.0, le=100)
    """k: each phase limit L becomes (L² + (k σ_noise)²)^½ at each candidate, σ_noise the
    spread that noise alone gives the measure at that echo's samples (σ/|I| per sample, the
    RMS over the echo; ψ_AB both channels'; the split phase × the beams' noise gain;
    processing/backscatter/echo_criteria.py). Noise alone stays below 1.5 σ_noise
    (docs/single_targets.md): 2 keeps weak single echoes without widening the limit for
    strong ones. 0: the fixed limits alone, as EK60 and Echoview apply them (the reference);
    without a noise level (detection not by a noise threshold) the fixed limits apply."""
    minimum_echo_spacing: NonNegativeReal = Field(1.0, le=100)
    """param_minimum_echo_spacing: another echo in the same beam (within one azimuth
    resolution) closer in range than this many nominal pulse lengths rejects both."""
    echo_length_level_db: PositiveReal = Field(6.0, le=30)
    """Level below the peak (dB) at which the echo length is measured (Echoview's pulse length
    determination level); the SONAR-netCDF4 convention and the issue's criteria use 6 dB."""
    sidelobe_db: NonNegativeReal = Field(20.0, le=100)
    """A detection within 2.5 range cells of one this much stronger (dB) is its range or azimuth
    sidelobe (or grating ghost), not a target (rule ``sidelobe``); 0 turns the rule off."""
    near_field: bool = True
    """Compensate TS for the transmitter's and the receive beam's near field at the located
    position (processing/backscatter/target_strength.py); false: the far-field pattern only,
    as echosounders compensate (TS then reads ≈ 53/r² dB low on axis: 0.1 dB at 23 m)."""

    @model_validator(mode="after")
    def _durations(self):
        if not self.minimum_echo_duration < self.maximum_echo_duration:
            raise ValueError(f"minimum_echo_duration ({self.minimum_echo_duration}) must be less "
                             f"than maximum_echo_duration ({self.maximum_echo_duration})")
        return self


#: SingleTargetSettings field -> SONAR-netCDF4 2.0 SingleTarget variable (and its unit)
SONAR_NETCDF4_PARAMETERS = {
    "ts_threshold_db": ("param_TS_threshold", "dB"),
    "gain_compensation_db": ("param_gain_compensation", "dB"),
    "minimum_echo_duration": ("param_minimum_echo_duration", "1"),
    "maximum_echo_duration": ("param_maximum_echo_duration", "1"),
    "maximum_phase_deviation": ("param_maximum_phase_deviation", "arc_degree"),
    "minimum_echo_spacing": ("param_minimum_echo_spacing", "1"),
}


class ProcessingSettings(ConfigModel):
    """All processing settings."""

    image: ImageSettings = ImageSettings()
    detect: DetectSettings = DetectSettings()
    count: CountSettings = CountSettings()
    track: TrackSettings = TrackSettings()
    single_target: SingleTargetSettings = SingleTargetSettings()


def load_settings(path: str | Path) -> ProcessingSettings:
    """Read processing settings from their own YAML file (same keys as a scene's
    ``processing`` section). Raises :class:`processing.base.config.ConfigError`."""
    data, marks = read_yaml(path)
    return validate_file(ProcessingSettings, data, file=path, marks=marks)
