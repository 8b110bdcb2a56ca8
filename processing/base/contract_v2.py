"""The SONAR-netCDF4 2.0 layout abacus writes, as data: one table of groups, types and variables.

Beside :mod:`processing.base.contract` (1.0, the default, what echopype opens) and in its manner
(echopype's ``echodata/convention/*.yml``): the groups, netCDF4 types (enums, variable-length
vectors), variables with their netCDF type, dimensions, ``units``, ``long_name`` and further
attributes, and the obligation of each (the convention's M, MA, O, R; ``V`` for abacus' own
vendor extensions). :mod:`processing.base.sonar_netcdf2` writes a file from this table and checks
a file against it (:func:`processing.base.sonar_netcdf2.check_file`); the test of the writer
checks the same file against the convention's own definition tables (tests/data/sonar-netcdf4-2.0,
ICES, tag v2.0), independently of this table. docs/dataset.md describes the layout and its choices.

Layout choices (docs/dataset.md, "SONAR-netCDF4 2.0"):

* The receiver is ONE beam of /Sonar/Beam_group1 and its elements are that beam's sub-beams
  (``subbeam``; subarrays A and B named per sub-beam by the vendor variable ``subbeam_subarray``):
  as EK80's four quadrants are sub-beams of one split-aperture beam, ABACUS' elements are
  sub-apertures of one receive aperture whose azimuth (beamforming) and elevation (A/B
  interferometry) both come from combining them. The beam type is the vendor value
  ``split_aperture_element_array`` appended to the convention's ``beam_t`` enum.
* Transmitter and receiver are separate transducers of /Platform (``transmit_only``,
  ``receive_only``); beam pointing is the convention's rotations (``rx_beam_rotation_*``,
  ``tx_beam_rotation_*``) and, as a vendor extension, unit direction vectors ``beam_direction_*``.
* The gridded group (/Sonar/Grid_group1) holds the MVBS of the fan: the convention's gridded data
  are per ``frequency`` with one beam each (``beam_reference``), so the fan's beams at the one
  transmit frequency are its ``frequency`` entries, each naming its beam.
"""
from __future__ import annotations

from dataclasses import dataclass

from processing.base.contract import Attribute, attribute_table, markdown_main

__all__ = ["CONVENTIONS_V2", "VERSION", "NcType", "NcVar", "NcGroup", "GROUPS_V2", "group_v2",
           "BEAM_GROUP_V2", "SINGLE_TARGET_GROUP", "GRID_GROUP", "ROOT", "ENVIRONMENT", "PLATFORM",
           "PROVENANCE", "SONAR", "VENDOR", "TIME_UNITS", "BEAM_TYPE_ELEMENT_ARRAY", "markdown",
           "MARKDOWN_BEGIN", "MARKDOWN_END"]

VERSION = "2.0"
CONVENTIONS_V2 = "CF-1.7, SONAR-netCDF4-2.0, ACDD-1.3"
#: the time unit abacus writes (the convention allows this one and 1601-01-01)
TIME_UNITS = "nanoseconds since 1970-01-01 00:00:00Z"
#: the vendor value of ``beam_t``: one beam whose sub-beams are the receive elements
BEAM_TYPE_ELEMENT_ARRAY = 101

ROOT = "/"
ENVIRONMENT = "/Environment"
PLATFORM = "/Platform"
PROVENANCE = "/Provenance"
SONAR = "/Sonar"
BEAM_GROUP_V2 = "/Sonar/Beam_group1"
SINGLE_TARGET_GROUP = "/Sonar/Beam_group1/SingleTarget"
GRID_GROUP = "/Sonar/Grid_group1"
VENDOR = "/Vendor_specific"


@dataclass(frozen=True)
class NcType:
    """A netCDF4 user type of a group: an enum (``members``: (name, value) pairs) or a
    variable-length vector (``kind="vlen"``) of ``base`` ("float", "int")."""

    name: str
    kind: str
    base: str
    members: tuple = ()


@dataclass(frozen=True)
class NcVar:
    """One variable of a 2.0 group.

    Attributes
    ----------
    name : str
    dims : tuple of str
    type : str
        "float" (32-bit), "double", "int", "short", "byte", "uint64", "string", or a type of
        this group or an enclosing one (an enum or vlen, :class:`NcType`).
    units, long_name : str or None
    obligation : {"M", "MA", "O", "R", "V"}
        The convention's obligation; "V": abacus' vendor extension.
    attrs : tuple of (str, object)
        Further attributes written with it (``valid_range``, ``coordinates``, ...).
    doc : str
        Its meaning, where the long_name does not say it.
    """

    name: str
    dims: tuple
    type: str
    units: str | None
    long_name: str | None
    obligation: str
    attrs: tuple = ()
    doc: str = ""

    def attributes(self) -> dict:
        out = {}
        if self.units is not None:
            out["units"] = self.units
        if self.long_name is not None:
            out["long_name"] = self.long_name
        out.update(self.attrs)
        return out


@dataclass(frozen=True)
class NcGroup:
    """One group: node path, meaning, user types, variables, attributes (:class:`Attribute` of
    the 1.0 table: ``mandatory`` is the convention's M)."""

    path: str
    doc: str
    variables: tuple
    attributes: tuple = ()
    types: tuple = ()

    def variable(self, name: str) -> NcVar | None:
        return next((v for v in self.variables if v.name == name), None)

    def attribute(self, name: str) -> Attribute | None:
        return next((a for a in self.attributes if a.name == name), None)


def _v(name, dims, type_, units, long_name, obligation, *attrs, doc=""):
    return NcVar(name, tuple(dims.split()), type_, units, long_name, obligation, tuple(attrs), doc)


_PT = "ping_time"
_COORDS = ("coordinates", "ping_time platform_latitude platform_longitude")
_GRID_COORDS = ("coordinates", "ping_axis platform_latitude platform_longitude")
_ANGLE = ("valid_range", (-180.0, 180.0))
_TILT = ("valid_range", (-90.0, 90.0))
_WIDTH = ("valid_range", (0.0, 360.0))
_POSITIVE = ("valid_min", 0.0)
_SUBSTITUTE = ("substitute_value_used", 0)
_EBA = ("valid_range", (0.0, 12.566370614359172))
_TIME_ATTRS = (("axis", "T"), ("calendar", "gregorian"), ("standard_name", "time"))
_NQP = (("flag_meanings", "no_non_quantitative_processing"), ("flag_values", 0))


def _rotations(prefix: str, dims: str) -> tuple:
    """``<prefix>_beam_rotation_phi/theta/psi``: the intrinsic z-y'-x'' rotation of the beam
    frame (beam axis z) from the platform frame (x forward, y starboard, z down)."""
    side = "receive" if prefix == "rx" else "transmit"
    return (
        _v(f"{prefix}_beam_rotation_phi", dims, "float", "arc_degree",
           f"{side} beam angular rotation about the _x_ axis", "M", _ANGLE),
        _v(f"{prefix}_beam_rotation_theta", dims, "float", "arc_degree",
           f"{side} beam angular rotation about the _y_ axis", "M", _TILT),
        _v(f"{prefix}_beam_rotation_psi", dims, "float", "arc_degree",
           f"{side} beam angular rotation about the _z_ axis", "M", _ANGLE),
    )


def _pulse(axis: str, tx: str, *substitute) -> tuple:
    """The transmit pulse variables of a beam or grid group, on (axis, tx)."""
    d = f"{axis} {tx}"
    return (
        _v("transmit_duration_nominal", d, "float", "s", "Nominal duration of transmitted pulse", "M",
           _POSITIVE, *substitute),
        _v("transmit_frequency_start", d, "float", "Hz", "Start frequency in transmitted pulse", "M",
           ("standard_name", "sound_frequency"), _POSITIVE),
        _v("transmit_frequency_stop", d, "float", "Hz", "Stop frequency in transmitted pulse", "M",
           ("standard_name", "sound_frequency"), _POSITIVE),
        _v("transmit_bandwidth", d, "float", "Hz", "Nominal bandwidth of transmitted pulse", "O", _POSITIVE),
        _v("transmit_type", d, "transmit_t", None, "Type of transmitted pulse", "M"),
        _v("beamwidth_transmit_major", d, "float", "arc_degree",
           "Half power one-way transmit beam width along major (horizontal) axis of beam", "MA", _WIDTH),
        _v("beamwidth_transmit_minor", d, "float", "arc_degree",
           "Half power one-way transmit beam width along minor (vertical) axis of beam", "MA", _WIDTH),
        _v("sample_time_offset", d, "float", "s",
           "Time offset that is subtracted from the timestamp of each sample", "M"),
    )


def _platform_per_ping() -> tuple:
    c = _COORDS
    return (
        _v("platform_latitude", _PT, "double", "degrees_north", "latitude", "M",
           ("valid_range", (-90.0, 90.0)), ("standard_name", "Platform latitude"), c,
           doc="NaN: a simulated sonar has no geographic position"),
        _v("platform_longitude", _PT, "double", "degrees_east", "longitude", "M",
           ("valid_range", (-180.0, 180.0)), ("standard_name", "Platform longitude"), c,
           doc="NaN: a simulated sonar has no geographic position"),
        _v("platform_heading", _PT, "float", "degrees_north", "Platform heading(true)", "M",
           ("standard_name", "platform_orientation"), ("valid_range", (0.0, 360.0)), c,
           doc="abacus' yaw (heading change from the world x axis), modulo 360"),
        _v("platform_pitch", _PT, "float", "arc_degree", "pitch angle", "M",
           ("standard_name", "platform_pitch_angle"), ("valid_range", (-90.0, 90.0)), c),
        _v("platform_roll", _PT, "float", "arc_degree", "roll angle", "M",
           ("standard_name", "platform_roll_angle"), c),
        _v("platform_vertical_offset", _PT, "float", "m",
           "Platform vertical distance from reference point to the water line", "M", c,
           doc="abacus' heave (the water line below the reference point: the platform up)"),
    )


# ------------------------------------------------------------------ the groups
_ROOT = NcGroup(ROOT, "the file", (), (
    Attribute("Conventions", "CF, SONAR-netCDF4 and ACDD", CONVENTIONS_V2, True),
    Attribute("date_created", "ISO 8601, UTC", mandatory=True),
    Attribute("keywords", "the sonar model and type", mandatory=True),
    Attribute("sonar_convention_authority", "", "ICES", True),
    Attribute("sonar_convention_name", "", "SONAR-netCDF4", True),
    Attribute("sonar_convention_version", "", VERSION, True),
    Attribute("summary", "the scene's description", mandatory=True),
    Attribute("title", "what the data are", mandatory=True),
    Attribute("data_kind", "vendor: \"simulated\" or \"recorded\""),
    Attribute("software_name", "vendor: abacus"),
    Attribute("software_version", "vendor: abacus' version"),
    Attribute("source", "vendor: the file a recording was converted from"),
))

_ENV = NcGroup(ENVIRONMENT, "the water", (
    _v("frequency", "frequency", "float", "Hz", "Acoustic frequency", "M",
       ("standard_name", "sound_frequency"), _POSITIVE),
    _v("absorption_indicative", "frequency", "float", "dB/m", "Indicative acoustic absorption", "M",
       _POSITIVE),
    _v("sound_speed_indicative", "", "float", "m/s", "Indicative sound speed", "M",
       ("standard_name", "speed_of_sound_in_sea_water"), _POSITIVE),
    _v("temperature", "", "double", "degree_Celsius", "vendor: where the absorption came from", "V"),
    _v("salinity", "", "double", "PSU", "vendor: where the absorption came from", "V"),
    _v("depth", "", "double", "m", "vendor: depth at which absorption was evaluated", "V"),
    _v("ph", "", "double", "1", "vendor: where the absorption came from", "V"),
))

_PLATFORM = NcGroup(PLATFORM, "the transducers: a transmitter and a receiver, and the sonar's pose", (
    _v("transducer_ids", "transducer", "string", None, "Transducer identification", "MA"),
    _v("transducer_function", "transducer", "transducer_type_t", None,
       "Transducer function (transmit_only, receive_only, monostatic)", "M"),
    *(_v(f"transducer_offset_{a}", "transducer", "float", "m",
         f"_{a}_-axis distance from the platform coordinate system origin to the sonar transducer", "R")
      for a in "xyz"),
    *(_v(f"transducer_rotation_{a}", "transducer", "float", "arc_degree",
         f"Extrinsic rotation about the _{a}_-" + ("azis" if a == "z" else "axis")
         + " from the transducer to reference coordinate systems", "R", _ANGLE) for a in "xyz"),
    _v("position_ids", "position", "string", None, "Position sensor identification", "MA",
       doc="none: a simulated platform has no position sensor (the dimension is empty)"),
    _v("MRU_ids", "MRU", "string", None, "MRU identification", "MA",
       doc="none: a simulated platform has no motion sensor (the dimension is empty)"),
    _v("sonar_position", "world_axis", "double", "m", "vendor: sonar-frame origin in the world frame",
       "V"),
    _v("sonar_rotation", "world_axis sonar_axis", "double", "1",
       "vendor: columns: sonar axes x_s, y_s, z_s in world coordinates", "V"),
    _v("ping_sonar_position", "ping_time world_axis", "double", "m",
       "vendor: sonar-frame origin in the world frame, per ping", "V"),
    _v("ping_sonar_rotation", "ping_time world_axis sonar_axis", "double", "1",
       "vendor: columns: sonar axes in world coordinates, per ping", "V"),
    _v("ping_time", "ping_time", "uint64", TIME_UNITS, "vendor: the pings of the per-ping pose", "V",
       *_TIME_ATTRS),
), (
    Attribute("platform_name", "the platform"),
    Attribute("platform_type", "the platform's kind"),
), types=(NcType("transducer_type_t", "enum", "byte",
                 (("receive_only", 0), ("transmit_only", 1), ("monostatic", 3))),))

_PROVENANCE = NcGroup(PROVENANCE, "what made the file", (
    _v("source_filenames", "filenames", "string", None, "Source filenames", "MA"),
), (
    Attribute("conversion_software_name", "abacus", mandatory=True),
    Attribute("conversion_software_version", "abacus' version", mandatory=True),
    Attribute("conversion_time", "ISO 8601, UTC", mandatory=True),
    Attribute("history", "what was done"),
    Attribute("scene_sha256", "vendor: the scene's SHA-256"),
    Attribute("scene_text", "vendor: the fully resolved scene (YAML)"),
    Attribute("seed", "vendor: the seed of every draw"),
))

_SONAR = NcGroup(SONAR, "the sonar", (
    _v("transmit_frequency_center", "", "double", "Hz", "vendor: the transmit centre frequency", "V"),
    _v("calibration_gain", "", "double", "count m",
       "vendor: G = k S: image peak (counts) of a target of backscatter amplitude 1 m at 1 m on "
       "the transmit axis", "V"),
    _v("two_way_elevation_width", "calibration_azimuth", "double", "rad",
       "vendor: integral over elevation of |E_t|^2 |D_rx|^2 cos(elevation), per azimuth", "V"),
    _v("calibration_azimuth", "calibration_azimuth", "double", "rad",
       "vendor: azimuths of two_way_elevation_width", "V"),
    *(_v(f"tx_element_{a}", "tx_element", "double", "m",
         f"vendor: transmitter element centres ({a}, sonar frame)", "V") for a in "xyz"),
    _v("tx_element_width", "tx_element", "double", "m", "vendor: transmitter element widths", "V"),
    _v("tx_element_height", "tx_element", "double", "m", "vendor: transmitter element heights", "V"),
    _v("tx_element_rotation", "tx_element", "double", "rad",
       "vendor: transmitter element rotations about z", "V"),
    _v("tx_element_weight", "tx_element", "double", "1", "vendor: transmitter element weights", "V"),
), (
    Attribute("sonar_manufacturer", "who made the sonar"),
    Attribute("sonar_model", "the model"),
    Attribute("sonar_serial_number", "its serial number"),
    Attribute("sonar_software_name", "its software"),
    Attribute("sonar_software_version", "its software's version"),
    Attribute("sonar_type", "\"multibeam\": the convention's vocabulary (\"omni-sonar\") has no "
              "word for it yet (docs/dataset.md)", "multibeam", True),
    Attribute("taper", "vendor: the pulse's amplitude taper"),
    Attribute("sweep", "vendor: the pulse's frequency sweep"),
    Attribute("variant", "vendor: the ABACUS variant"),
    Attribute("frame", "vendor: the sonar frame's axes"),
), types=(
    NcType("beam_stabilisation_t", "enum", "byte", (("not_stabilised", 0), ("stabilised", 1))),
    NcType("beam_t", "enum", "byte", (("single", 0), ("split_aperture_angles", 1),
                                      ("split_aperture_4_subbeams", 2), ("split_aperture_3_subbeams", 3),
                                      ("split_aperture_3_1_subbeams", 4),
                                      ("split_aperture_element_array", BEAM_TYPE_ELEMENT_ARRAY))),
    NcType("conversion_equation_t", "enum", "byte", tuple((f"type_{i}", i) for i in range(1, 6))),
    NcType("transmit_t", "enum", "byte", (("CW", 0), ("LFM", 1), ("HFM", 2))),
))

_BEAM = NcGroup(BEAM_GROUP_V2, "the receiver's samples: one beam, its elements the sub-beams", (
    _v("beam", "beam", "string", None, "Beam name", "M"),
    _v("ping_time", _PT, "uint64", TIME_UNITS, "Time-stamp of each ping", "M", *_TIME_ATTRS, _COORDS),
    _v("frequency", "frequency", "float", "Hz", "Calibration gain frequencies", "MA", _POSITIVE),
    _v("calibrated_frequency", "frequency", "float", "Hz", "Calibration gain frequencies", "M",
       _POSITIVE, doc="the transmit centre frequency, at which calibration_gain holds"),
    _v("backscatter_r", "ping_time beam subbeam", "sample_t", "1",
       "Raw backscatter measurements (real part)", "M", doc="complex baseband samples, ADC counts"),
    _v("backscatter_i", "ping_time beam subbeam", "sample_t", "1",
       "Raw backscatter measurements (imaginary part)", "MA", doc="complex baseband samples, ADC counts"),
    _v("sample_count", "ping_time beam subbeam", "int", "1",
       "Number of samples per ping in each beam, and optionally subbeam", "O", ("valid_min", 0)),
    _v("beam_type", "", "beam_t", None, "Type of beam", "M"),
    _v("beam_stabilisation", _PT, "beam_stabilisation_t", None, "Beam stabilisation applied (or not)",
       "M", _COORDS),
    _v("non_quantitative_processing", _PT, "short", None,
       "Presence or not of non-quantitative processing applied to the backscattering data (sonar "
       "specific)", "M", *_NQP, _COORDS),
    _v("beamwidth_receive_major", f"{_PT} beam", "float", "arc_degree",
       "Half power one-way receive beam width along major (horizontal) axis of beam", "M", _WIDTH,
       _SUBSTITUTE, doc="one element's: the sector every formed beam of the fan lies in"),
    _v("beamwidth_receive_minor", f"{_PT} beam", "float", "arc_degree",
       "Half power one-way receive beam width along minor (vertical) axis of beam", "M", _WIDTH,
       _SUBSTITUTE),
    _v("equivalent_beam_angle", f"{_PT} beam", "float", "sr", "Equivalent beam angle", "M", _EBA,
       _SUBSTITUTE, doc="two-way solid angle of the transmitter with one element (NaN unknown)"),
    *_rotations("rx", f"{_PT} beam"),
    *_rotations("tx", f"{_PT} tx_beam"),
    _v("sample_interval", _PT, "float", "s", "Interval between recorded raw data samples", "M",
       _POSITIVE, _COORDS),
    _v("blanking_interval", f"{_PT} beam", "float", "s",
       "Amount of time during reception where samples are discarded", "M", ("valid_min", 0.0)),
    *_pulse(_PT, "tx_beam", _SUBSTITUTE),
    _v("transmit_pulse_model_r", f"{_PT} tx_beam", "pulse_t", None,
       "Real part of the model of the transmit pulse", "MA", ("valid_min", -1.0), ("valid_max", 1.0)),
    _v("transmit_pulse_model_i", f"{_PT} tx_beam", "pulse_t", None,
       "Imaginary part of the model of the transmit pulse", "MA", ("valid_min", -1.0), ("valid_max", 1.0)),
    _v("receive_transducer_index", "beam", "int", None, "Receive transducer index", "MA", ("valid_min", 0)),
    _v("transmit_transducer_index", f"{_PT} tx_beam", "int", None, "Transmit transducer index", "MA",
       ("valid_min", 0)),
    _v("transmit_beam_index", f"{_PT} beam", "int", None,
       "Transmit beam index associated with the given beam", "MA", ("valid_min", 0)),
    *_platform_per_ping(),
    _v("sound_speed_at_transducer", _PT, "float", "m/s",
       "Indicative sound speed at ping time and transducer depth", "O", _POSITIVE,
       ("standard_name", "speed_of_sound_in_sea_water"), _COORDS),
    # vendor: what the convention has no place for
    _v("ping_index", _PT, "int", None, "vendor: the scene's index of each ping", "V"),
    *(_v(f"beam_direction_{a}", "beam", "float", "1",
         f"vendor: receive beam direction unit vector, {a} (platform frame)", "V") for a in "xyz"),
    *(_v(f"tx_beam_direction_{a}", "tx_beam", "float", "1",
         f"vendor: transmit beam direction unit vector, {a} (platform frame)", "V") for a in "xyz"),
    _v("subbeam", "subbeam", "string", None, "vendor: sub-beam (element) name: subarray and index", "V"),
    _v("subbeam_subarray", "subbeam", "string", None, "vendor: the subarray of each element (A, B)", "V"),
    _v("subbeam_index_in_subarray", "subbeam", "int", None, "vendor: each element's index in its subarray",
       "V"),
    *(_v(f"subbeam_{a}", "subbeam", "double", "m", f"vendor: element centres, {a} (sonar frame)", "V")
      for a in "xyz"),
    _v("subbeam_width", "subbeam", "double", "m", "vendor: element widths", "V"),
    _v("subbeam_height", "subbeam", "double", "m", "vendor: element heights", "V"),
    _v("subbeam_rotation", "subbeam", "double", "rad", "vendor: element rotations about z", "V"),
    _v("adc_clipped_samples", f"{_PT} subbeam", "int", "1", "vendor: samples clipped by the ADC (I or Q)",
       "V"),
), (
    Attribute("beam_mode", "", "vertical", True),
    Attribute("conversion_equation_type", "type_4 (complex samples, matched filter with the pulse "
              "model); calibrated with the vendor calibration_gain", mandatory=True),
    Attribute("mode", "vendor: interferometric, normal or combined"),
    Attribute("adc_scale_counts", "vendor"), Attribute("adc_quantized", "vendor"),
    Attribute("adc_bits", "vendor"), Attribute("noise_enabled", "vendor"),
    Attribute("noise_sigma_counts", "vendor"), Attribute("noise_bandwidth_hz", "vendor"),
    Attribute("receiver_bandwidth_hz", "vendor"),
), types=(NcType("sample_t", "vlen", "float"), NcType("angle_t", "vlen", "float"),
          NcType("pulse_t", "vlen", "float")))

_ST = "ping_time beam"
_SINGLE = NcGroup(SINGLE_TARGET_GROUP, "the single targets of each ping", (
    _v("single_target_count", _ST, "int", None, "Number of single target detection in each beam, per ping",
       "O", ("valid_min", 0)),
    _v("single_target_identifier", _ST, "target_identifier", None, "Index of single target detected", "MA",
       doc="the track id where the target was tracked, else a number of its own"),
    _v("single_target_range", _ST, "target_range", "m", "Range of single target detected", "MA"),
    _v("single_target_alongship_angle", _ST, "target_angle", "arc_degree",
       "Single target arrival angle in the minor beam coordinate", "MA", _ANGLE,
       doc="elevation: the angle in the sonar y-z plane (interferometry)"),
    _v("single_target_athwartship_angle", _ST, "target_angle", "arc_degree",
       "Single target arrival angle in the major beam coordinate", "MA", _ANGLE,
       doc="azimuth: the angle in the sonar x-z plane (beamforming)"),
    _v("compensated_TS", f"{_ST} frequency", "target_TS", "dB",
       "Calculated Target Strength (re 1 m^2^) after compensation for off-axis angle for each "
       "frequency of the receive echo from spectral analysis of the FM pulse or frequency of the CW "
       "pulse", "MA"),
    _v("uncompensated_TS", f"{_ST} frequency", "target_TS", "dB",
       "Calculated Target Strength (re 1 m^2^) uncompensated for off-axis angle for each frequency of "
       "the receive echo from spectral analysis of the FM pulse or frequency of the CW pulse", "MA"),
    _v("param_TS_threshold", _ST, "float", "dB",
       "Minimum TS (re 1 m^2^) threshold for single target detection", "MA"),
    _v("param_gain_compensation", _ST, "float", "dB",
       "Maximum one-way angular gain compensation for single target detection", "MA"),
    _v("param_minimum_echo_duration", _ST, "float", "1",
       "Minimimum normalized echo duration for single target detection relative to nominal pulse "
       "duration", "MA"),
    _v("param_maximum_echo_duration", _ST, "float", "1",
       "Maximimum normalized echo duration for single target detection relative to nominal pulse "
       "duration", "MA"),
    _v("param_maximum_phase_deviation", _ST, "float", "arc_degree",
       "Maximimum phase standard deviation for single target detection", "MA"),
    _v("param_minimum_echo_spacing", _ST, "float", "1",
       "Minimum distance between two single targets detected relative to nominal pulse duration", "MA"),
    _v("param_TSf_processing_window_duration", _ST, "float", "s",
       "Duration of the processing window for spectral analysis around the peak echo value for single "
       "target detection", "MA"),
    *(_v(f"single_target_{a}", _ST, "target_range", "m",
         f"vendor: position of the single target, {a} (sonar frame)", "V") for a in "xyz"),
), types=(NcType("target_identifier", "vlen", "int"), NcType("target_range", "vlen", "float"),
          NcType("target_angle", "vlen", "float"), NcType("target_TS", "vlen", "float")))

_GA = "ping_axis"
_GRID = NcGroup(GRID_GROUP, "the MVBS of the fan: Sv per ping bin, range bin and formed beam", (
    _v("beam", "beam", "string", None, "Beam name", "M"),
    _v("frequency", "frequency", "float", "Hz",
       "Frequency of the receive echo from spectral analysis of the FM pulse or frequency of the CW "
       "pulse.", "M", _POSITIVE, doc="the transmit centre frequency, once per formed beam"),
    _v("beam_reference", "frequency", "string", None, "Reference to the beam for a given frequency", "M"),
    _v("backscatter_type", "frequency", "backscatter_type_t", None, "Backscatter type for gridded data", "M"),
    _v("ping_axis_interval_type", "", "ping_axis_interval_type_t", None,
       "Interval type for regridding the data in ping axis", "MA"),
    _v("ping_axis_interval_value", "", "float", None, "Ping axis interval for regridding the data", "M"),
    _v("range_axis_interval_type", "", "range_axis_interval_type_t", None,
       "Interval type for regridding the data in range axis", "M"),
    _v("range_axis_interval_value", "", "float", None, "Range axis interval for regridding the data", "M"),
    _v("cell_ping_time", f"{_GA} tx_beam", "uint64", TIME_UNITS, "Mean time-stamp of each cell", "M",
       *_TIME_ATTRS, ("coordinates", "ping_axis platform_latitude platform_longitude")),
    _v("integrated_backscatter", f"{_GA} range_axis frequency", "float", "dB",
       "Integrated backscatter of the raw backscatter measurements sampled in this cell for each "
       "frequency.", "M", ("comment", "Sv, dB re 1 m-1; NaN where the cell holds noise only"),
       doc="Sv of the cell (dB re 1 m⁻¹), the mean of linear s_v"),
    _v("beamwidth_receive_major", f"{_GA} beam", "float", "arc_degree",
       "Half power one-way receive beam width along major (horizontal) axis of beam", "M", _WIDTH),
    _v("beamwidth_receive_minor", f"{_GA} beam", "float", "arc_degree",
       "Half power one-way receive beam width along minor (vertical) axis of beam", "M", _WIDTH),
    *_rotations("rx", f"{_GA} beam"),
    *_rotations("tx", f"{_GA} tx_beam"),
    _v("beam_stabilisation", _GA, "beam_stabilisation_t", None, "Beam stabilisation applied (or not)", "M",
       _GRID_COORDS),
    _v("beam_type", "beam", "beam_t", None, "Type of beam", "M"),
    _v("equivalent_beam_angle", f"{_GA} beam", "float", "sr", "Equivalent beam angle", "M", _EBA),
    _v("non_quantitative_processing", _GA, "short", None,
       "Presence or not of non-quantitative processing applied to the backscattering data (sonar "
       "specific)", "M", *_NQP, _GRID_COORDS),
    _v("sample_interval", f"{_GA} beam", "float", "s", "Interval between recorded raw data samples", "M",
       _POSITIVE, _GRID_COORDS),
    _v("blanking_interval", f"{_GA} beam", "float", "s",
       "Amount of time during reception where samples are discarded", "M", ("valid_min", 0.0)),
    *_pulse(_GA, "tx_beam"),
    _v("receive_transducer_index", "beam", "int", None, "Receive transducer index", "MA", ("valid_min", 0)),
    *(_v(f"cell_{n}", f"{_GA} range_axis beam", "double", u, n, "M",
         ("valid_range", r), ("standard_name", f"Platform {n}"),
         ("coordinates", "ping_axis cell_latitude cell_longitude"),
         doc="NaN: a simulated sonar has no geographic position")
      for n, u, r in (("latitude", "degrees_north", (-90.0, 90.0)),
                      ("longitude", "degrees_east", (-180.0, 180.0)))),
    _v("cell_depth", "range_axis beam", "float", "m", "Cell depth below water line", "M",
       doc="world z of the cell's centre (the sonar at rest), positive down"),
    # vendor
    _v("sv_linear", f"{_GA} range_axis frequency", "float", "m-1",
       "vendor: mean volume backscattering coefficient s_v of the cell", "V"),
    _v("range_axis_start", "range_axis", "float", "m", "vendor: range of the cell's near edge", "V"),
    _v("range_axis_stop", "range_axis", "float", "m", "vendor: range of the cell's far edge", "V"),
    _v("ping_axis_first_ping", _GA, "int", None, "vendor: the first ping (row) of the cell", "V"),
    _v("ping_axis_last_ping", _GA, "int", None, "vendor: the last ping (row) of the cell", "V"),
    _v("beam_azimuth", "beam", "float", "arc_degree", "vendor: azimuth of each formed beam (sonar frame)",
       "V"),
), (
    Attribute("beam_mode", "", "vertical", True),
    Attribute("conversion_equation_type", "as the beam group's", mandatory=True),
    Attribute("noise_sigma_counts", "vendor: the noise subtracted (2 sigma^2 per cell)"),
    Attribute("image_group", "vendor: the subarray image the grid is made from"),
), types=(
    NcType("backscatter_type_t", "enum", "byte", (("Sv", 0), ("Sa", 1))),
    NcType("range_axis_interval_type_t", "enum", "byte", (("Range", 0), ("Depth", 1))),
    NcType("ping_axis_interval_type_t", "enum", "byte",
           (("Time_seconds", 0), ("Distance_nautical_miles", 1), ("Distance_meters", 2), ("Number_of_ping", 3))),
))

#: node path -> its group, in the order of the file
GROUPS_V2 = {g.path: g for g in (_ROOT, _ENV, _PLATFORM, _PROVENANCE, _SONAR, _BEAM, _SINGLE, _GRID)}


def group_v2(path: str) -> NcGroup:
    """The table's row of a 2.0 group by node path (``"/Sonar/Beam_group1"``)."""
    try:
        return GROUPS_V2["/" + path.strip("/")]
    except KeyError:
        raise KeyError(f"{path} is not a group of the SONAR-netCDF4 2.0 table "
                       f"(groups: {', '.join(GROUPS_V2)})") from None


# ------------------------------------------------------------------ docs/dataset.md
MARKDOWN_BEGIN = ("<!-- SONAR-netCDF4 2.0 tables: generated by `python -m processing.base.contract_v2 "
                  "--markdown`; edit processing/base/contract_v2.py -->")
MARKDOWN_END = "<!-- end of SONAR-netCDF4 2.0 tables -->"


def markdown() -> str:
    """The 2.0 table as docs/dataset.md shows it, between :data:`MARKDOWN_BEGIN` and
    :data:`MARKDOWN_END`: every group's variables (type, dimensions, units, obligation — V for
    abacus' vendor extensions) and attributes.

    Returns
    -------
    str
        Markdown, ending in a newline.
    """
    lines = [MARKDOWN_BEGIN, "", "| group | variable | type | dims | units | obligation | meaning |",
             "|---|---|---|---|---|---|---|"]
    for g in GROUPS_V2.values():
        for i, v in enumerate(g.variables):
            meaning = (v.doc or v.long_name or "").replace("|", "\\|")
            lines.append("| " + " | ".join([f"`{g.path}`" if i == 0 else "", f"`{v.name}`", v.type,
                                            ", ".join(v.dims), v.units or "", v.obligation, meaning]) + " |")
    lines += ["", *attribute_table(GROUPS_V2.values())]
    lines += ["", "| group | type | kind | values |", "|---|---|---|---|"]
    for g in GROUPS_V2.values():
        for t in g.types:
            values = ", ".join(f"{k} = {v}" for k, v in t.members) if t.kind == "enum" else f"vectors of {t.base}"
            lines.append(f"| `{g.path}` | `{t.name}` | {t.kind} | {values} |")
    lines += ["", MARKDOWN_END]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    """``python -m processing.base.contract_v2 --markdown``: print the tables of docs/dataset.md."""
    return markdown_main("processing.base.contract_v2", markdown, argv)


if __name__ == "__main__":
    raise SystemExit(main())
