"""The data contract as data: one table of SONAR-netCDF4 1.0 groups, variables, units, attributes.

In the manner of echopype's ``echodata/convention/``: the convention is written once, here, and
everything else reads it — the builder every writer goes through
(:mod:`processing.base.groups`: the simulator, ``abacus convert``), the contract check, the
typed readers' group names, and the variable tables of docs/dataset.md
(``python -m processing.base.contract --markdown`` prints them; a test keeps the page current).

Each group of :data:`GROUPS` lists its variables (:class:`Variable`: dimensions, units, dtype
kind, ``long_name`` and further attributes, whether processing cannot do without it) and its
attributes (:class:`Attribute`: fixed values the builder fills in). Units follow one rule: a
quantity carries its unit (``"1"`` when it is dimensionless, counts included); text, indices,
identifiers and 0/1 flags carry none (``units=None``).

The group paths are constants (:data:`ELEMENT_GROUP`, ...), relative to the root as
``tree[ELEMENT_GROUP]`` takes them; :data:`GROUPS` is keyed by node path (``"/Sonar/Beam_group1"``).
The /Processing groups are products of processing: their paths are here
(:data:`PRODUCT_GROUPS`), their variables with the modules that write them.

This module imports nothing but the standard library (the table is cheap to read).
"""
from __future__ import annotations

import sys
from dataclasses import dataclass

__all__ = ["ROOT_GROUP", "ENVIRONMENT_GROUP", "PLATFORM_GROUP", "PROVENANCE_GROUP", "SONAR_GROUP",
           "BEAM_GROUP_NAME", "ELEMENT_GROUP", "TRUTH_GROUP", "ARRIVALS_GROUP", "PROCESSING_GROUP", "DETECTIONS_GROUP",
           "COUNTS_GROUP", "SV_GROUP", "TRACKS_GROUP", "LABELS_GROUP", "PRODUCT_GROUPS", "LEGACY_ELEMENT_GROUP",
           "LEGACY_TRUTH_GROUP", "ECHOPYPE_GROUPS", "FLAT_HOST", "FLAT_MAP_ATTR", "flat_name", "CONVENTIONS", "CHANNEL", "KINDS", "Variable", "Attribute", "Group",
           "GROUPS", "group_spec", "node_path", "markdown", "attribute_table", "markdown_main", "MARKDOWN_BEGIN",
           "MARKDOWN_END"]

# ------------------------------------------------------------------ group paths
ROOT_GROUP = "/"
ENVIRONMENT_GROUP = "Environment"
PLATFORM_GROUP = "Platform"
PROVENANCE_GROUP = "Provenance"
SONAR_GROUP = "Sonar"
#: the one beam group: its name in /Sonar's ``beam_group_name``, and its path
BEAM_GROUP_NAME = "Beam_group1"
ELEMENT_GROUP = f"{SONAR_GROUP}/{BEAM_GROUP_NAME}"
#: abacus' ground truth (simulated data only)
TRUTH_GROUP = "Vendor_specific"
#: abacus' per-arrival ground truth (simulated data, only when a run records arrivals)
ARRIVALS_GROUP = f"{TRUTH_GROUP}/Arrivals"

#: processing's products, each written by the module named
PROCESSING_GROUP = "Processing"
DETECTIONS_GROUP = f"{PROCESSING_GROUP}/Detections"
COUNTS_GROUP = f"{PROCESSING_GROUP}/Counts"
SV_GROUP = f"{PROCESSING_GROUP}/Sv"
TRACKS_GROUP = f"{PROCESSING_GROUP}/Tracks"
LABELS_GROUP = f"{PROCESSING_GROUP}/Labels"
PRODUCT_GROUPS = {
    PROCESSING_GROUP: "processing.records: images and how they were made",
    DETECTIONS_GROUP: "processing.records: one row per detection",
    COUNTS_GROUP: "processing.records: counts and densities per ping",
    SV_GROUP: "processing.backscatter.sv: MVBS grid and NASC",
    TRACKS_GROUP: "processing.tracking.tracks: tracks and track points",
    LABELS_GROUP: "processing.imaging.labels: what made each image cell (simulated data with arrivals)",
}

#: the groups echopype's EchoData knows (its convention table, echodata/convention/1.0.yml): its
#: repr names every group of a file by that table (any other group: ``KeyError``), so a file
#: abacus writes holds no other group. The others — the /Processing products and
#: /Vendor_specific/Arrivals — lie flat in :data:`FLAT_HOST` in the file, each variable,
#: dimension and attribute of group ``G`` named :func:`flat_name` ``(G, name)``, the way back in
#: the attribute :data:`FLAT_MAP_ATTR` (processing/base/file_layout.py; docs/dataset.md, "In the
#: file"). In memory they are groups.
ECHOPYPE_GROUPS = ("/", "/Environment", "/Platform", "/Platform/NMEA", "/Provenance", "/Sonar",
                   *(f"/Sonar/Beam_group{i}" for i in range(1, 5)), "/Vendor_specific")
#: where the other groups lie in the file: SONAR-netCDF4 1.0 leaves vendor content to this group
FLAT_HOST = TRUTH_GROUP
#: the attribute of :data:`FLAT_HOST` listing each flattened group's variables, coordinates,
#: dimensions and attributes (JSON)
FLAT_MAP_ATTR = "abacus_flat_groups_json"


def flat_name(group: str, name: str) -> str:
    """The name in the file of variable, dimension or attribute ``name`` of a group that lies flat
    in :data:`FLAT_HOST`: the group path with dots, then the name (``Processing.Sv.Sv``)."""
    return f"{group.strip('/').replace('/', '.')}.{name}"


#: the layout abacus wrote before SONAR-netCDF4 1.0 (read by `abacus convert`)
LEGACY_ELEMENT_GROUP = "Simulation/Element_group1"
LEGACY_TRUTH_GROUP = "Simulation/Ground_truth"

CONVENTIONS = "CF-1.7, SONAR-netCDF4-1.0, ACDD-1.3"
#: the one SONAR-netCDF4 channel abacus writes: the receiver, whose beams are its elements
CHANNEL = "abacus-receiver"

#: dtype kinds of the table -> numpy kinds a value may have (ints widen to floats when written)
KINDS = {"f": "fiu", "i": "iu", "U": "USO", "M": "M"}
_KIND_WORDS = {"f": "float", "i": "int", "U": "text", "M": "time"}


# ------------------------------------------------------------------ the table's rows
@dataclass(frozen=True)
class Variable:
    """One variable (or coordinate) of a group.

    Attributes
    ----------
    name : str
    dims : tuple of str
        Its dimensions, in order (``()`` for a scalar).
    units : str or None
        The ``units`` attribute; None for text, indices, identifiers and flags.
    kind : {"f", "i", "U", "M"}
        dtype kind: float, integer, text, datetime64.
    doc : str
        Its meaning (docs/dataset.md); defaults to ``long_name``.
    long_name : str or None
        The ``long_name`` attribute written with it.
    mandatory : bool
        Processing cannot read a dataset without it (:func:`processing.base.dataset.read_record`).
    coord : bool
        A coordinate, not a data variable.
    attrs : tuple of (str, str)
        Further attributes written with it (``frame``, ``nan_means``).
    when : str
        When abacus writes it, if not always (e.g. "with a moving platform").
    """

    name: str
    dims: tuple
    units: str | None
    kind: str
    doc: str = ""
    long_name: str | None = None
    mandatory: bool = False
    coord: bool = False
    attrs: tuple = ()
    when: str = ""

    def attributes(self) -> dict:
        """The attributes written with the variable: units, long_name, then the rest."""
        out = {}
        if self.units is not None:
            out["units"] = self.units
        if self.long_name is not None:
            out["long_name"] = self.long_name
        out.update(self.attrs)
        return out

    @property
    def meaning(self) -> str:
        return self.doc or self.long_name or ""


@dataclass(frozen=True)
class Attribute:
    """One attribute of a group.

    Attributes
    ----------
    name, doc : str
    value : str or None
        A fixed value every writer writes (the builder fills it in); None when writers give it.
    mandatory : bool
        Every dataset abacus writes has it.
    """

    name: str
    doc: str = ""
    value: str | None = None
    mandatory: bool = False


@dataclass(frozen=True)
class Group:
    """One group: node path, meaning, variables and attributes.

    Attributes
    ----------
    path : str
        Node path from the root (``"/"``, ``"/Sonar/Beam_group1"``).
    doc : str
    variables : tuple of Variable
        Data variables and coordinates.
    attributes : tuple of Attribute
    mandatory : bool
        Processing cannot read a dataset without it.
    """

    path: str
    doc: str
    variables: tuple
    attributes: tuple = ()
    mandatory: bool = False

    def variable(self, name: str) -> Variable | None:
        """The row of ``name``, or None when the group has no such variable."""
        return next((v for v in self.variables if v.name == name), None)

    def attribute(self, name: str) -> Attribute | None:
        """The row of attribute ``name``, or None."""
        return next((a for a in self.attributes if a.name == name), None)


def _v(name: str, dims: str, units: str | None, kind: str, doc: str = "", **kw) -> Variable:
    return Variable(name, tuple(dims.split()), units, kind, doc, **kw)


def _c(name: str, dims: str, units: str | None, kind: str, doc: str = "", **kw) -> Variable:
    return Variable(name, tuple(dims.split()), units, kind, doc, coord=True, **kw)


def _geometry(prefix: str, dim: str, where: str, *, centres_mandatory: bool, when: str = "") -> tuple:
    """``<prefix>_x/_y/_z`` centres, ``_width/_height`` and ``_rotation`` of an element array."""
    centre = dict(mandatory=centres_mandatory)
    return (
        *(_v(f"{prefix}_{a}", dim, "m", "f", f"{where} element centres (sonar frame)", **centre)
          for a in "xyz"),
        *(_v(f"{prefix}_{a}", dim, "m", "f", f"{where} element sizes: TS and the beam model need "
             "them", when=when) for a in ("width", "height")),
        _v(f"{prefix}_rotation", dim, "rad", "f", f"{where} element rotations about z", when=when),
    )


_PER_PING = "channel ping_time"
_PER_BEAM = "channel beam"
_SIMULATED = "in simulated data"
_MOVING = "with a moving platform"

# ------------------------------------------------------------------ the table
_ROOT = Group(ROOT_GROUP, "the file: the convention and what made the data", (), (
    Attribute("conventions", "CF, SONAR-netCDF4 and ACDD", CONVENTIONS, True),
    Attribute("sonar_convention_authority", "the convention's authority", "ICES", True),
    Attribute("sonar_convention_name", "the convention", "SONAR-netCDF4", True),
    Attribute("sonar_convention_version", "its version", "1.0", True),
    Attribute("keywords", "the sonar model, as echopype reads it", mandatory=True),
    Attribute("title", "what the data are", mandatory=True),
    Attribute("summary", "the scene's description (simulated data)"),
    Attribute("date_created", "ISO 8601, UTC", mandatory=True),
    Attribute("software_name", "abacus (simulated data)"),
    Attribute("software_version", "abacus' version (simulated data)"),
    Attribute("data_kind", "\"simulated\" or \"recorded\"", mandatory=True),
    Attribute("source", "the file a recording was converted from"),
    Attribute("converted_from", "the layout a file was converted from (`abacus convert`)"),
))

_ENVIRONMENT = Group(f"/{ENVIRONMENT_GROUP}", "the water", (
    _v("sound_speed_indicative", "", "m/s", "f", "c used for ranges and phases", mandatory=True),
    _v("absorption_indicative", "frequency", "dB/m", "f",
       "α along `frequency`; processing takes it at the transmit centre frequency (a scalar is "
       "accepted too)", long_name="indicative absorption at the transmit centre frequency"),
    _v("temperature", "", "degree_Celsius", "f", "where α came from", when=_SIMULATED),
    _v("salinity", "", "PSU", "f", "where α came from", when=_SIMULATED),
    _v("depth", "", "m", "f", "where α came from", when=_SIMULATED,
       long_name="depth at which absorption was evaluated"),
    _v("ph", "", "1", "f", "where α came from", when=_SIMULATED),
    _c("frequency", "frequency", "Hz", "f", "the frequencies of `absorption_indicative`"),
), mandatory=True)

_PLATFORM = Group(f"/{PLATFORM_GROUP}", "where the sonar is", (
    _v("sonar_position", "world_axis", "m", "f", "sonar origin in the world frame",
       long_name="sonar-frame origin in the world frame (x forward, y starboard, z down)"),
    _v("sonar_rotation", "world_axis sonar_axis", "1", "f",
       "columns: sonar axes in world coordinates (the mounting pose, at rest)",
       long_name="columns: sonar axes x_s, y_s, z_s in world coordinates"),
    *(_v(f"transducer_offset_{a}", "channel", "m", "f",
         "SONAR-netCDF4's transducer offset: `sonar_position`",
         long_name=f"transducer {a} offset from the platform origin") for a in "xyz"),
    _v("ping_sonar_position", "ping_time world_axis", "m", "f",
       "the sonar origin at each ping (processing locates each detection in its own ping's pose)",
       long_name="sonar-frame origin in the world frame, per ping", when=_MOVING),
    _v("ping_sonar_rotation", "ping_time world_axis sonar_axis", "1", "f",
       "the sonar axes at each ping", long_name="columns: sonar axes in world coordinates, per ping",
       when=_MOVING),
    _v("roll", "ping_time", "arc_degree", "f", "attitude of each ping ([conventions.md](conventions.md), "
       "\"Platform motion\")", long_name="roll, starboard down positive", when=_MOVING),
    _v("pitch", "ping_time", "arc_degree", "f", "attitude of each ping ([conventions.md](conventions.md), "
       "\"Platform motion\")", long_name="pitch, bow up positive", when=_MOVING),
    _v("heading", "ping_time", "arc_degree", "f", "attitude of each ping ([conventions.md](conventions.md), "
       "\"Platform motion\")", long_name="yaw (heading change), clockwise from above positive",
       when=_MOVING),
    _v("vertical_offset", "ping_time", "m", "f", "heave of each ping, positive up",
       long_name="heave, positive up", when=_MOVING),
    _c("world_axis", "world_axis", None, "U", "x, y, z of the world frame"),
    _c("sonar_axis", "sonar_axis", None, "U", "x, y, z of the sonar frame"),
    _c("channel", "channel", None, "U", "the channel of the transducer offsets"),
    _c("ping_time", "ping_time", None, "M", "the pings of the per-ping pose", when=_MOVING),
), (
    Attribute("mount", "what the pose variables are (a moving platform)"),
))

_PROVENANCE = Group(f"/{PROVENANCE_GROUP}", "what made the data (simulated data)", (
    _v("source_filenames", "filenames", None, "U",
       "the file the data came from (the scene file, or the recording converted), as echopype's "
       "Provenance holds it (its combine_echodata reads it)"),
    _c("filenames", "filenames", None, "i", "index of the source files"),
), (
    Attribute("scene_text", "the fully resolved scene (YAML)"),
    Attribute("scene_sha256", "its SHA-256"),
    Attribute("scene_file", "the scene file, if any"),
    Attribute("seed", "the seed of every draw"),
    Attribute("versions", "versions of everything that shapes the numbers (JSON)"),
    Attribute("stages_run", "the stages that ran, comma-separated"),
    Attribute("stage_seconds_json", "wall time of each stage that ran, s (JSON {stage: seconds}): an "
              "attribute, not a variable, because two runs' timings differ by nature and echopype's "
              "combine_echodata refuses differing variables (it keeps every file's attributes in its "
              "Provenance)"),
    Attribute("stage_calls_json", "times each stage was entered (JSON {stage: calls})"),
    Attribute("rays_cast_json", "rays cast per purpose (JSON)"),
    Attribute("command", "the command line"),
    Attribute("conversion_software_name", "what wrote the file (abacus), as echopype's Provenance says it"),
    Attribute("conversion_software_version", "its version"),
    Attribute("conversion_time", "when (ISO 8601, UTC)"),
))

_SONAR = Group(f"/{SONAR_GROUP}", "the sonar: pulse, transmitter, calibration, beam groups", (
    _v("transmit_frequency_start", "", "Hz", "f", "the LFM pulse"),
    _v("transmit_frequency_stop", "", "Hz", "f", "the LFM pulse"),
    _v("transmit_frequency_center", "", "Hz", "f", "the transmit centre frequency", mandatory=True),
    _v("transmit_bandwidth", "", "Hz", "f", "the transmit bandwidth", mandatory=True),
    _v("transmit_duration_nominal", "", "s", "f", "the pulse length"),
    _v("beamwidth_transmit_major", "", "arc_degree", "f",
       "transmitter 3 dB width in azimuth (the counting volume)",
       long_name="transmit 3 dB beamwidth in azimuth (sonar x-z plane)"),
    _v("beamwidth_transmit_minor", "", "arc_degree", "f",
       "transmitter 3 dB width in elevation (the counting volume)",
       long_name="transmit 3 dB beamwidth in elevation"),
    *(_v(f"replica_{p}", "replica_sample", "1", "f",
         "u(j/fs): what the matched filter correlates with (float32)", mandatory=True,
         long_name="transmit pulse u(j/fs), complex baseband") for p in "ri"),
    *_geometry("tx_element", "tx_element", "transmitter", centres_mandatory=True),
    _v("tx_element_weight", "tx_element", "1", "f", "transmitter element weights", mandatory=True),
    _v("calibration_gain", "", "counts m", "f",
       "G = k S: image peak of a target of backscatter amplitude 1 m at 1 m on the transmit axis",
       long_name="G = k S: image peak of a target of backscatter amplitude 1 m at 1 m on the "
                 "transmit axis (see acoustics/sonar/calibration.py)"),
    _v("two_way_elevation_width", "calibration_azimuth", "rad", "f",
       "Φ(θ) = ∫ \\|E_t\\|² \\|D_rx\\|² cos φ dφ: the sonar's part of echo integration's "
       "equivalent beam (`acoustics/sonar/calibration.py`)",
       long_name="integral over elevation of |E_t|^2 |D_rx|^2 cos(elevation), per azimuth: the "
                 "sonar's part of echo integration's equivalent beam"),
    _v("beam_group_name", "beam_group", None, "U", "the one beam group"),
    _v("beam_group_descr", "beam_group", None, "U", "what it holds"),
    _c("channel_all", "channel_all", None, "U", "the channel ids of the beam groups (`abacus-receiver`)"),
    _c("beam_group", "beam_group", None, "U", "the beam groups"),
    _c("replica_sample", "replica_sample", None, "i", "sample index of the replica"),
    _c("calibration_azimuth", "calibration_azimuth", "rad", "f", "azimuths of `two_way_elevation_width`"),
), (
    Attribute("sonar_manufacturer", "who made the sonar (empty when unknown)"),
    Attribute("sonar_model", "the sonar model (ABACUS, custom; empty when unknown)"),
    Attribute("sonar_serial_number", "its serial number (empty when unknown)"),
    Attribute("sonar_software_name", "its software (empty when unknown)"),
    Attribute("sonar_software_version", "its software's version (empty when unknown)"),
    Attribute("sonar_type", "the kind of sonar", "multibeam", True),
    Attribute("transmit_type", "the pulse", "LFM", True),
    Attribute("taper", "the pulse's amplitude taper"),
    Attribute("sweep", "the pulse's frequency sweep"),
    Attribute("mode", "the receiver's mode"),
    Attribute("variant", "the ABACUS variant, or \"explicit\" arrays"),
    Attribute("frame", "the sonar frame's axes"),
), mandatory=True)

_BEAM_GROUP = Group(f"/{ELEMENT_GROUP}", "the per-element samples: one channel, one beam per element", (
    *(_v(f"backscatter_{p}", "channel ping_time range_sample beam", "ADC counts", "f",
         "per-element complex baseband samples (float32)", mandatory=True,
         long_name="complex baseband samples per receive element") for p in "ri"),
    _v("beam_type", "channel", None, "U", "\"single\": each beam one element",
       long_name="each beam is one element's own (unsteered) beam"),
    *(_v(f"beam_direction_{a}", _PER_BEAM, "1", "f", "each element's normal in the platform frame",
         long_name="beam (element normal) direction in the platform frame", when=_SIMULATED)
      for a in "xyz"),
    *(_v(f"beamwidth_receive_{a}", _PER_BEAM, "arc_degree", "f", "each element's 3 dB widths",
         when=_SIMULATED) for a in ("major", "minor")),
    *(_v(f"beamwidth_transmit_{a}", _PER_BEAM, "arc_degree", "f", "the transmitter's 3 dB widths",
         when=_SIMULATED) for a in ("major", "minor")),
    _v("equivalent_beam_angle", _PER_BEAM, "dB re 1 sr", "f",
       "10 log10 of the two-way solid angle of the transmitter with one element",
       long_name="10 log10 of the two-way equivalent solid angle of the transmitter and one element",
       when=_SIMULATED),
    _v("sample_interval", _PER_PING, "s", "f", "1/fs", mandatory=True),
    _v("blanking_interval", _PER_PING, "s", "f",
       "sample k is at `blanking_interval + k·sample_interval − sample_time_offset` after the "
       "start of transmission (0 if absent)",
       long_name="time of sample 0 after the start of transmission"),
    _v("sample_time_offset", _PER_PING, "s", "f",
       "sample k is at `blanking_interval + k·sample_interval − sample_time_offset` after the "
       "start of transmission (0 if absent)"),
    _v("transmit_frequency_start", _PER_PING, "Hz", "f", "the pulse of each ping"),
    _v("transmit_frequency_stop", _PER_PING, "Hz", "f", "the pulse of each ping"),
    _v("transmit_duration_nominal", _PER_PING, "s", "f", "the pulse of each ping", when=_SIMULATED),
    _v("transmit_bandwidth", _PER_PING, "Hz", "f", "the pulse of each ping"),
    _v("transmit_type", "channel", None, "U", "\"LFM\"", when=_SIMULATED),
    _v("beam_stabilisation", "ping_time", None, "i", "0: not stabilised", when=_SIMULATED),
    _v("non_quantitative_processing", "ping_time", None, "i", "0: no processing", when=_SIMULATED),
    *_geometry("element", "beam", "receiver", centres_mandatory=True),
    _v("element_subarray", "beam", None, "U", "which subarray each element is (A, B)", mandatory=True),
    _v("element_index_in_subarray", "beam", None, "i", "each element's index in its subarray"),
    _v("adc_clipped_samples", "ping_time beam", "1", "i", "samples clipped by the ADC (I or Q)",
       long_name="samples clipped by the ADC (I or Q)", when="when the ADC quantises"),
    _c("channel", "channel", None, "U", "the receiver (`abacus-receiver`)"),
    _c("ping_time", "ping_time", None, "M", "ping p is at `pings.start_time + p · interval_s`",
       mandatory=True),
    _c("ping_index", "ping_time", None, "i", "the scene's index of each ping (0, 1, ... if absent)"),
    _c("range_sample", "range_sample", None, "i", "sample index"),
    _c("beam", "beam", None, "U", "element names: subarray and index (`A0` … `B15`)"),
), (
    Attribute("mode", "\"interferometric\" (default), \"normal\" or \"combined\""),
    Attribute("adc_scale_counts", "ADC counts per unit pressure"),
    Attribute("adc_quantized", "1 when the ADC quantises"),
    Attribute("adc_bits", "ADC resolution"),
    Attribute("noise_enabled", "1 when receiver noise was added"),
    Attribute("noise_sigma_counts", "receiver noise σ per quadrature component (counts)"),
    Attribute("noise_bandwidth_hz", "the noise band"),
    Attribute("receiver_bandwidth_hz", "the receiver band"),
    Attribute("beam_mode", "\"vertical\""),
    Attribute("conversion_equation_type", "what the samples are"),
), mandatory=True)

_FRAME_SONAR = (("frame", "sonar"),)
_FRAME_WORLD = (("frame", "world"),)
_TRUTH = Group(f"/{TRUTH_GROUP}", "abacus' ground truth: every target of every ping, one row each, "
               "along `ping_time` (simulated data)", (
    _v("target_ping_index", "ping_time", None, "i", "the ping of each row"),
    *(_v(f"target_{a}", "ping_time", "m", "f", "position in the sonar frame", attrs=_FRAME_SONAR)
      for a in "xyz"),
    _v("target_world_x", "ping_time", "m", "f", "position in the world frame", attrs=_FRAME_WORLD),
    _v("target_world_y", "ping_time", "m", "f", "position in the world frame", attrs=_FRAME_WORLD),
    _v("target_world_z", "ping_time", "m", "f", "position in the world frame",
       attrs=(("frame", "world (depth)"),)),
    _v("target_range", "ping_time", "m", "f", "range, azimuth, elevation in the sonar frame"),
    _v("target_azimuth", "ping_time", "rad", "f", "range, azimuth, elevation in the sonar frame"),
    _v("target_elevation", "ping_time", "rad", "f", "range, azimuth, elevation in the sonar frame"),
    _v("target_backscatter_amplitude", "ping_time", "m", "f", "ρ", long_name="rho = sqrt(sigma_bs)"),
    _v("target_ts", "ping_time", "dB re 1 m^2", "f", "TS (−inf where ρ = 0)", long_name="-inf where rho = 0",
       attrs=(("nan_means", "-inf: rho = 0 (no echo)"),)),
    _v("target_phase", "ping_time", "rad", "f", "extra phase"),
    _v("target_group", "ping_time", None, "i", "population (−1 = explicit point)",
       long_name="-1 explicit point, else population index"),
    _v("target_id", "ping_time", None, "i",
       "identity, persistent across pings for points and populations with `redraw: false`: point "
       "i is i, target k of population j is (j + 1)·10⁶ + k",
       long_name="identity: point i is i, fish k of population j is (j + 1) x 1e6 + k; "
                 "persistent across pings for points and populations with redraw: false"),
    _v("target_velocity_world_x", "ping_time", "m/s", "f",
       "world-frame velocity at the ping (0 for targets that hold their place)", attrs=_FRAME_WORLD),
    _v("target_velocity_world_y", "ping_time", "m/s", "f",
       "world-frame velocity at the ping (0 for targets that hold their place)", attrs=_FRAME_WORLD),
    _v("target_velocity_world_z", "ping_time", "m/s", "f",
       "world-frame velocity at the ping (0 for targets that hold their place)",
       attrs=(("frame", "world (depth rate)"),)),
    _v("target_in_counting_volume", "ping_time", None, "i",
       "1 inside the transmitter's 3 dB beam and the image's range limits"),
    _v("target_shadowed", "ping_time", None, "i", "1 where a mesh blocks the direct path",
       long_name="1 where a mesh blocks the direct path (no direct echo)"),
    _c("ping_time", "ping_time", None, "M",
       "the time of each row's ping (repeated for every target of a ping): the rows' dimension is "
       "`ping_time` so that echopype's combine_echodata appends the truth of two files as it appends "
       "their pings (docs/interop.md); targets per ping are the rows of each `target_ping_index`"),
), (
    Attribute("counting_volume", "what the counting volume is"),
    Attribute("counting_range_min_m", "its near range limit (scalars, not a list: echopype's "
              "combine_echodata compares attributes one value at a time)"),
    Attribute("counting_range_max_m", "its far range limit"),
    Attribute("counting_azimuth_halfwidth_rad", "its half-width in azimuth"),
    Attribute("counting_elevation_halfwidth_rad", "its half-width in elevation"),
    Attribute("counting_volume_m3", "its volume (13.8 m³ for the thesis)"),
))

_ARRIVAL = "arrival"
_WITH_ARRIVALS = "with effects.arrivals (`abacus simulate --arrivals`)"


def _a(name: str, units: str | None, kind: str, doc: str, **kw) -> Variable:
    return _v(f"arrival_{name}", _ARRIVAL, units, kind, doc, when=_WITH_ARRIVALS, **kw)


_ARRIVALS = Group(f"/{ARRIVALS_GROUP}", "abacus' per-arrival ground truth: one row per path of "
                  "every ping (a vendor-specific extension; docs/dataset.md, \"Arrivals\")", (
    _a("ping_index", None, "i", "the ping of each row"),
    _a("target_id", None, "i", "the target whose echo it is (`target_id` of /Vendor_specific); "
       "−1 for a facet"),
    _a("sequence", None, "U", "interactions in propagation order, `-`-joined: T target, S/F/O "
       "specular bounce off a surface/floor/obstacle, RS/RF/RO a surface/floor/obstacle facet "
       "(reverberation), M a mesh target's facet (`T`, `S-T`, `T-S`, `S-T-S`, `F-T-S`, `RF`)"),
    _a("scatterer", None, "U", "`target <id>`, or `<boundary or mesh target>#<facet>`"),
    _a("boundary", None, "U", "the boundary or mesh target of a facet (empty for a target)"),
    _a("facet", None, "i", "the facet's index in its mesh (−1 for a target)"),
    _a("via", None, "U", "the boundaries bounced off, in order, `;`-separated "
       "(`name#facet` for a curved one)"),
    _a("bounces", "1", "i", "specular bounces of the path (both legs)"),
    _a("delay", "s", "f", "two-way delay from the transmitter's phase centre to the receiver's"),
    _a("transmit_range", "m", "f", "transmit leg length, unfolded (through its bounces)"),
    _a("receive_range", "m", "f", "receive leg length, unfolded (through its bounces)"),
    _a("level", "dB re source level at 1 m", "f",
       "level at the receiver's phase centre without the sonar's directivities: 20 log10 |amplitude|"),
    _a("amplitude_r", "1", "f", "complex amplitude q g(r1) g(r2) e^{−jk(r1+r2)} (re the source "
       "level at 1 m), real and imaginary parts"),
    _a("amplitude_i", "1", "f", "complex amplitude q g(r1) g(r2) e^{−jk(r1+r2)} (re the source "
       "level at 1 m), real and imaginary parts"),
    _a("departure_azimuth", "rad", "f", "direction the path leaves the transmitter in (sonar frame)",
       attrs=_FRAME_SONAR),
    _a("departure_elevation", "rad", "f", "direction the path leaves the transmitter in (sonar frame)",
       attrs=_FRAME_SONAR),
    _a("azimuth", "rad", "f", "direction the path arrives from at the receiver (sonar frame)",
       attrs=_FRAME_SONAR),
    _a("elevation", "rad", "f", "direction the path arrives from at the receiver (sonar frame)",
       attrs=_FRAME_SONAR),
    _a("doppler", "Hz", "f", "Doppler shift −f0 (dL/dt)/c (0 without `effects.doppler`)"),
    _a("shadowed", None, "i", "1 where a mesh blocks the target's direct path"),
), (
    Attribute("alphabet", "the interaction alphabet of `arrival_sequence`"),
    Attribute("floor_db", "rows are kept down to this level (dB) below each ping's strongest "
              "(`none`: every row)"),
    Attribute("max_bounces", "`effects.max_bounces` of the run"),
    Attribute("transmit_reference_m", "the transmitter's phase centre (m, sonar frame): where "
              "delays and departure directions start"),
    Attribute("receive_reference_m", "the receiver's phase centre (m, sonar frame): where "
              "delays and arrival directions end"),
))

#: node path -> its group, in the order of the file
GROUPS = {g.path: g for g in (_ROOT, _ENVIRONMENT, _PLATFORM, _PROVENANCE, _SONAR, _BEAM_GROUP, _TRUTH,
                              _ARRIVALS)}


def node_path(group: str) -> str:
    """The node path of a group given either way (``"Sonar/Beam_group1"`` or with a leading
    slash): ``"/Sonar/Beam_group1"``; the root is ``"/"``."""
    return "/" + group.strip("/")


def group_spec(group: str) -> Group:
    """The table's row of a group.

    Parameters
    ----------
    group : str
        A path as the constants give it (``ELEMENT_GROUP``) or a node path.

    Raises
    ------
    KeyError
        Not a group of the contract (the /Processing products are not in the table).
    """
    try:
        return GROUPS[node_path(group)]
    except KeyError:
        raise KeyError(f"{node_path(group)} is not a group of the data contract "
                       f"(groups: {', '.join(GROUPS)})") from None


# ------------------------------------------------------------------ docs/dataset.md
MARKDOWN_BEGIN = "<!-- contract tables: generated by `python -m processing.base.contract --markdown`; edit processing/base/contract.py -->"
MARKDOWN_END = "<!-- end of contract tables -->"


def _meaning(v: Variable) -> str:
    text = v.meaning
    return f"{text} (only {v.when})" if v.when else text


def _variable_rows(g: Group) -> list:
    """Rows of the variables table; consecutive variables alike but for their names share one."""
    rows, keys = [], []
    for v in g.variables:
        key = (v.coord, v.dims, v.units, v.kind, v.mandatory, _meaning(v))
        if keys and keys[-1] == key:
            rows[-1][0].append(v.name)
            continue
        keys.append(key)
        rows.append(([v.name], v))
    out = []
    for names, v in rows:
        label = ", ".join(f"`{n}`" for n in names)
        out.append([("coord " if v.coord else "") + label, ", ".join(v.dims), v.units or "",
                    _KIND_WORDS[v.kind], "yes" if v.mandatory else "", _meaning(v)])
    return out


def markdown() -> str:
    """The contract's tables as docs/dataset.md shows them, between :data:`MARKDOWN_BEGIN` and
    :data:`MARKDOWN_END`: the variables (and coordinates) of every group, then the attributes.

    Returns
    -------
    str
        Markdown, ending in a newline.
    """
    lines = [MARKDOWN_BEGIN, "",
             "| group | variable | dims | units | type | mandatory | meaning |",
             "|---|---|---|---|---|---|---|"]
    for g in GROUPS.values():
        rows = _variable_rows(g)
        if not rows:
            continue
        for i, r in enumerate(rows):
            lines.append("| " + " | ".join([f"`{g.path}`" if i == 0 else ""] + r) + " |")
    lines += ["", *attribute_table(GROUPS.values()), "", MARKDOWN_END]
    return "\n".join(lines) + "\n"


def attribute_table(groups) -> list:
    """The markdown rows (header included) of the attributes of ``groups`` (objects with
    ``path`` and ``attributes`` of :class:`Attribute`): one table for either convention."""
    lines = ["| group | attribute | value | mandatory | meaning |", "|---|---|---|---|---|"]
    for g in groups:
        for i, a in enumerate(g.attributes):
            lines.append("| " + " | ".join([f"`{g.path}`" if i == 0 else "", f"`{a.name}`",
                                            a.value or "", "yes" if a.mandatory else "", a.doc]) + " |")
    return lines


def markdown_main(module: str, render, argv=None) -> int:
    """``python -m <module> --markdown``: print ``render()`` (a contract's docs/dataset.md
    tables); exit status 2 with a usage line otherwise."""
    args = sys.argv[1:] if argv is None else list(argv)
    if args != ["--markdown"]:
        print(f"usage: python -m {module} --markdown", file=sys.stderr)
        return 2
    sys.stdout.write(render())
    return 0


def main(argv=None) -> int:
    """``python -m processing.base.contract --markdown``: print the tables of docs/dataset.md."""
    return markdown_main("processing.base.contract", markdown, argv)


if __name__ == "__main__":
    raise SystemExit(main())
