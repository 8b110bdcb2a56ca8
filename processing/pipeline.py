"""One chain in memory: a record's stages pass typed results, not the dataset tree.

``image → detect → count``, ``detect → single targets → track`` and ``image → Sv`` run on one
:class:`RecordChain`: the dataset is read once (:func:`processing.base.dataset.read_record`),
the settings are parsed once, and each stage hands the next a typed result
(:class:`~processing.imaging.images.Images`, :class:`Detected`, the counts as arrays). xarray
appears only where a record is read (:meth:`RecordChain.detected` of a file that already holds
detections) or written (the public facades in :mod:`processing.records`,
:mod:`processing.tracking.tracks`, :mod:`processing.backscatter.sv`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.counting_volume import CountingVolume
from processing.base.contract import (DETECTIONS_GROUP, ELEMENT_GROUP, PLATFORM_GROUP, PROCESSING_GROUP,
                                      PROVENANCE_GROUP, SONAR_GROUP, TRUTH_GROUP)
from processing.base.dataset import (DatasetError, as_tree, group_of, has_group, ping_indices, read_record,
                                     source_of)
from processing.base.config import parse_yaml, validate_file
from processing.settings import ImageSettings, ProcessingSettings, load_settings

__all__ = ["Detected", "RecordChain", "FLAG_COLUMNS", "resolve_settings", "noise_band_of",
           "volume_of", "pose_of", "AFTER_KEYS"]

#: detection columns that are flags (stored as int8, passed on as bool)
FLAG_COLUMNS = ("in_span", "in_volume", "elevation_clipped")


#: what only interferometry (the elevation) gives: NaN in normal and combined mode
AFTER_KEYS = ("count_after", "count_expected", "density_per_m3", "occupied_density_per_m3", "error_after",
              "hits_after", "misses_after", "false_alarms_after", "shared_cell_misses")


def resolve_settings(tree: xr.DataTree | None, settings=None) -> ProcessingSettings:
    """The processing settings to use: ``settings`` (a :class:`ProcessingSettings`, its
    ``image`` part, a dict, or a YAML file), else the ``processing`` section of the scene a
    dataset's /Provenance records, else the defaults.

    Raises
    ------
    processing.base.config.ConfigError
        Settings the schema refuses, with the key path.
    """
    if isinstance(settings, ProcessingSettings):
        return settings
    if isinstance(settings, ImageSettings):
        return ProcessingSettings.model_validate({"image": settings.model_dump(by_alias=True)})
    if isinstance(settings, (str, Path)):
        return load_settings(settings)
    if isinstance(settings, dict):
        return validate_file(ProcessingSettings, settings, file="<settings>")
    if settings is not None:
        raise TypeError(f"settings must be ProcessingSettings, ImageSettings, a dict or a YAML "
                        f"path, not {type(settings).__name__}")
    provenance = group_of(tree, PROVENANCE_GROUP) if tree is not None else None
    if provenance is not None:
        text = provenance.attrs.get("scene_text", "")
        if text:
            data, _ = parse_yaml(text, source="/Provenance scene_text")
            section = data.get("processing") if isinstance(data, dict) else None
            if section is not None:
                return validate_file(ProcessingSettings, section,
                                     file="/Provenance scene_text (processing section)")
    if tree is not None and _recorded(tree):
        # the 13–26 m default is the thesis scene's span, which a recording (a .mat file, a
        # plain SONAR-netCDF4 file) knows nothing of: its image spans the whole record
        return ProcessingSettings.model_validate({"image": {"range_m": None}})
    return ProcessingSettings()


def _recorded(tree: xr.DataTree) -> bool:
    """A recording, not a simulation: the root says ``data_kind: recorded``, or no scene made it
    (no /Provenance scene text)."""
    if str(tree.attrs.get("data_kind", "")) == "recorded":
        return True
    provenance = group_of(tree, PROVENANCE_GROUP)
    return provenance is None or not provenance.attrs.get("scene_text", "")


def noise_band_of(tree) -> float | None:
    """The receiver noise band (Hz) the dataset records (for the images' noise gain), or None."""
    attrs = tree[ELEMENT_GROUP].ds.attrs
    for key in ("noise_bandwidth_hz", "receiver_bandwidth_hz"):
        if key in attrs:
            return float(attrs[key])
    return None


def volume_of(tree: xr.DataTree, settings: ProcessingSettings, image_range_m=None):
    """The counting volume of a dataset: the transmitter's 3 dB beam (from /Sonar) x the image
    range (settings, else ``image_range_m``, else what /Processing recorded), with the overrides
    of ``settings.count``."""
    from processing.base.counting_volume import counting_volume
    sonar = group_of(tree, SONAR_GROUP)
    sonar = sonar if sonar is not None else xr.Dataset()
    cs = settings.count
    need = []
    for key, override in (("beamwidth_transmit_major", cs.azimuth_halfwidth),
                          ("beamwidth_transmit_minor", cs.elevation_halfwidth)):
        if key not in sonar and override is None:
            need.append(key)
    if need:
        raise DatasetError(f"the counting volume needs /Sonar/{' and /Sonar/'.join(need)} (transmit "
                           f"3 dB beamwidths, degrees) or count.azimuth_halfwidth_deg / "
                           f"count.elevation_halfwidth_deg in the settings")
    bw_az = np.radians(float(sonar["beamwidth_transmit_major"])) if "beamwidth_transmit_major" in sonar else 1.0
    bw_el = np.radians(float(sonar["beamwidth_transmit_minor"])) if "beamwidth_transmit_minor" in sonar else 1.0
    rng = settings.image.range_m
    if rng is None:
        rng = image_range_m
    if rng is None:
        pds = tree[PROCESSING_GROUP].ds
        rng = (pds.attrs["image_range_m"] if "image_range_m" in pds.attrs
               else (float(pds["image_range"][0]), float(pds["image_range"][-1])))
    return counting_volume(tx_beamwidth_az_rad=bw_az, tx_beamwidth_el_rad=bw_el,
                           image_range_m=rng, settings=cs)


def pose_of(tree):
    """The sonar's pose in the world frame, from /Platform.

    Returns
    -------
    (position_m, rotation) or None
        ``position_m`` shape (3,) (m, world frame: x forward, y starboard, z down) and
        ``rotation`` shape (3, 3), columns the sonar axes in world coordinates; for a moving
        platform one per ping: shapes (n_pings, 3) and (n_pings, 3, 3). None when the dataset
        has no pose (sonar frame = world frame).
    """
    ds = group_of(tree, PLATFORM_GROUP)
    if ds is not None and "sonar_rotation" in ds:
        if "ping_sonar_rotation" in ds:
            return (ds["ping_sonar_position"].values.astype(float),
                    ds["ping_sonar_rotation"].values.astype(float))
        return ds["sonar_position"].values.astype(float), ds["sonar_rotation"].values.astype(float)
    return None


@dataclass(frozen=True, eq=False)
class Detected:
    """What the detection stage passes on.

    Attributes
    ----------
    table : dict of ndarray, each shape (n_detections,)
        The detections (columns of :class:`processing.detection.detect.Detections`; flags bool).
    volume : CountingVolume
    range_resolution_m : float
        The images' range resolution (m): the scoring and single-target cells.
    azimuth_resolution_rad : float
        The images' azimuth resolution (rad).
    interferometric : bool
        Whether the images give an elevation (3-D positions).
    detections : Detections or None
        The detector's own record (noise fit, thresholds, notes); None when read from a file.
    first : Images or None
        One ping's images (their attributes: range axis, gains) when detected here.
    images : Images or None
        Every ping's images, when they were asked to be kept.
    """

    table: dict
    volume: CountingVolume
    range_resolution_m: float
    azimuth_resolution_rad: float
    interferometric: bool
    detections: object = None
    first: object = None
    images: object = None

    @property
    def n(self) -> int:
        return int(len(self.table.get("ping", ())))


class RecordChain:
    """A dataset's processing chain, its inputs read and its settings parsed once.

    Parameters
    ----------
    tree : xarray.DataTree, str or Path
        A dataset following the data contract, or its file.
    settings : ProcessingSettings, ImageSettings, dict or path, optional
        Default: the ``processing`` section the dataset's /Provenance records, else defaults.
    """

    def __init__(self, tree, settings=None):
        self.tree = as_tree(tree)
        self.settings: ProcessingSettings = resolve_settings(self.tree, settings)

    # ------------------------------------------------------------ inputs, once
    @cached_property
    def record(self):
        """The processing view of the dataset (:class:`~processing.base.dataset.SonarRecord`)."""
        return read_record(self.tree, source=source_of(self.tree))

    @cached_property
    def noise_band_hz(self) -> float | None:
        return noise_band_of(self.tree)

    @cached_property
    def pose(self):
        return pose_of(self.tree)

    @cached_property
    def ping_index(self) -> np.ndarray:
        """The scene's ping index of every ping, shape (n_pings,)."""
        return ping_indices(self.tree[ELEMENT_GROUP].ds)

    @cached_property
    def truth(self) -> dict | None:
        """``ping`` (row in the file) and ``position_m`` (n, 3, sonar frame) of every true target
        of the pings in the file, or None without ground truth."""
        try:
            gt = self.tree[TRUTH_GROUP].ds
        except KeyError:
            return None
        index_of = {int(p): i for i, p in enumerate(self.ping_index)}
        pings = gt["target_ping_index"].values.astype(int)
        keep = np.array([p in index_of for p in pings], bool)
        pos = np.stack([gt[f"target_{a}"].values for a in "xyz"], -1)[keep]
        return {"ping": np.array([index_of[p] for p in pings[keep]], int), "position_m": pos}

    # ------------------------------------------------------------------ stages
    def images(self, pings=None):
        """The images of every ping (or of ``pings``, row indices), formed from the samples.

        Returns
        -------
        Images
            ``image`` shape (n_pings, n_groups, n_range, n_beams), complex (ADC counts).
        """
        from processing.chain import record_pings
        from processing.imaging.images import form_images
        rec = self.record if pings is None else record_pings(self.record, np.asarray(pings, int))
        try:
            return form_images(rec, self.settings.image, noise_band_hz=self.noise_band_hz)
        except ValueError as exc:
            raise DatasetError(str(exc)) from None

    def _noise_magnitudes(self):
        """|I| of the noise-only dataset the settings name (``noise.source: noise_file``).

        The file goes through the file gate (:mod:`processing.base.files`): settings that are
        the dataset's own (its /Provenance scene, as ``abacus run`` processes) name it relative
        to that scene's folder and it must lie there, as ``abacus scene check`` checks; settings
        given otherwise (``--settings``, the API) name it relative to the working directory and
        it must lie there. ``ABACUS_ALLOW_OUTSIDE_FILES=1`` lifts the rule."""
        st = self.settings
        if st.detect.noise.source != "noise_file":
            return None
        from processing.base.dataset import open_tree
        from processing.base.files import FileRefused, check_file
        from processing.imaging.images import form_images
        name = st.detect.noise.file
        folder, key, home = Path.cwd(), "detect.noise.file", "the working directory"
        prov = group_of(self.tree, PROVENANCE_GROUP)
        scene_file = str(prov.attrs.get("scene_file", "")) if prov is not None else ""
        if scene_file and resolve_settings(self.tree).detect.noise == st.detect.noise:
            folder, key, home = Path(scene_file).parent, "processing.detect.noise.file", "the scene's folder"
        try:
            f = check_file(name, folder=folder, max_bytes=None, what="noise file", key=key,
                           allow_folder=True, folder_name=home,
                           accepts="a noise-only dataset (NetCDF4 or Zarr)")
        except FileRefused as exc:
            raise DatasetError(str(exc)) from None
        noise_rec = read_record(open_tree(f.path), source=str(f.path))
        try:
            ni = form_images(noise_rec, st.image, noise_band_hz=self.noise_band_hz)
        except ValueError as exc:
            raise DatasetError(f"{st.detect.noise.file}: {exc}") from None
        return np.abs(ni.image[:, ni.group_index(st.detect.image_group)])

    def detect(self, *, keep_images: bool = False) -> Detected:
        """Detections with 3-D positions (thesis chapter 5), a few pings imaged at a time
        (:func:`processing.chain.detect_record`).

        Parameters
        ----------
        keep_images : bool
            Also keep every ping's images (memory: all of them).

        Raises
        ------
        processing.detection.noise.NoiseEstimateError
            A noise-derived threshold on noise-free images.
        DatasetError
            Missing pieces of the dataset, named.
        """
        from processing.chain import detect_record
        from processing.detection.noise import NoiseEstimateError
        rec = self.record
        noise_mags = self._noise_magnitudes()
        try:
            # the attributes of the images (range axis, gains, resolution) from one ping
            first = self.images(pings=[0])
            volume = volume_of(self.tree, self.settings,
                               image_range_m=(float(first.range_m[0]), float(first.range_m[-1])))
            keep = range(rec.samples.shape[0]) if keep_images else ()
            det, kept = detect_record(rec, self.settings, volume, noise_band_hz=self.noise_band_hz,
                                      pose=self.pose, noise_magnitudes=noise_mags, keep_pings=keep)
        except ValueError as exc:
            if isinstance(exc, (NoiseEstimateError, DatasetError)):
                raise
            raise DatasetError(str(exc)) from None
        table = {k: np.asarray(v) for k, v in det.table.items()}
        for k in FLAG_COLUMNS:
            if k in table:
                table[k] = table[k].astype(bool)
        return Detected(table, volume, float(first.range_resolution_m),
                        float(first.azimuth_resolution_rad), bool(first.interferometric),
                        detections=det, first=first, images=kept)

    def detected(self) -> Detected:
        """The dataset's detections: those it holds (/Processing/Detections, read as a record),
        else detected here."""
        tree = self.tree
        if not has_group(tree, DETECTIONS_GROUP):
            return self.detect()
        ds = tree[DETECTIONS_GROUP].ds
        table = {k: ds[k].values for k in ds.data_vars if ds[k].dims == ("detection",)}
        for k in FLAG_COLUMNS:
            if k in table:
                table[k] = table[k].astype(bool)
        attrs = ds.attrs if "range_resolution_m" in ds.attrs else tree[PROCESSING_GROUP].ds.attrs
        pattrs = tree[PROCESSING_GROUP].ds.attrs
        return Detected(table, volume_of(tree, self.settings), float(attrs["range_resolution_m"]),
                        float(attrs["azimuth_resolution_rad"]),
                        bool(pattrs.get("interferometric", 1)))

    def count(self, detected: Detected) -> tuple[dict, dict]:
        """Counts and density per ping, and scores against the truth when there is one.

        Returns
        -------
        columns : dict of ndarray, each shape (n_pings,)
            count_before, count_after, density_per_m3, occupied_density_per_m3, with
            ``count.volume_edge`` "soft" count_expected (float: the expected number of fish
            inside given the located elevations and their σ), with
            ``count.coincidence_correction`` "poisson" count_corrected (float: the expected
            number of fish behind count_after, or behind count_expected with the soft edge),
            which the densities then use, and, with
            ground truth, true_in_volume, errors, hits/misses/false alarms
            (:func:`processing.detection.detect.score_all`); the values only interferometry
            gives are NaN without it.
        attrs : dict
            ``occupied_range_m`` (list, empty without an occupied layer), ``occupied_volume_m3``.
        """
        from processing.base.counting_volume import occupied_range
        from processing.detection.detect import score_all
        st = self.settings
        table, volume = detected.table, detected.volume
        n = len(self.ping_index)
        sidelobe = self.sidelobes(detected)
        res = score_all(table, self.truth, volume, n, dr=detected.range_resolution_m,
                        dtheta=detected.azimuth_resolution_rad, gate=st.count.gate_cells,
                        unresolved=st.count.unresolved_cells, sidelobe=sidelobe)
        if st.count.volume_edge == "soft" and detected.interferometric:
            # each detection counts with the probability that its fish lies inside
            res["count_expected"] = self._expected_count(detected, ~sidelobe)
            res["density_per_m3"] = res["count_expected"] / volume.volume_m3
        if st.count.coincidence_correction == "poisson" and detected.interferometric:
            # fish sharing a resolution cell give one echo: the expected number behind the count
            from processing.detection.coincidence import coincidence_coefficient, corrected_count
            a = coincidence_coefficient(volume, range_resolution_m=detected.range_resolution_m,
                                        azimuth_resolution_rad=detected.azimuth_resolution_rad,
                                        unresolved_cells=st.count.unresolved_cells)
            res["count_corrected"] = corrected_count(res.get("count_expected", res["count_after"]), a)
            res["density_per_m3"] = res["count_corrected"] / volume.volume_m3
        after = res.get("count_corrected", res.get("count_expected", res["count_after"]))
        # the density where the targets are: the range layer the run's located targets occupy
        layer = occupied_range(table["range_m"][table["in_volume"]], volume)
        occupied_m3 = volume.sector_volume_m3(layer) if layer is not None else 0.0
        res["occupied_density_per_m3"] = (after / occupied_m3 if occupied_m3 > 0
                                          else np.full(n, np.nan))
        if not detected.interferometric:
            # no elevation, so nothing is located in 3-D: "after interferometry" does not exist
            # (NaN, not a count of 0 that reads like an empty volume)
            for k in AFTER_KEYS:
                if k in res:
                    res[k] = np.full(n, np.nan)
        return res, {"occupied_range_m": list(layer) if layer is not None else [],
                     "occupied_volume_m3": occupied_m3}

    def _expected_count(self, detected: Detected, counted) -> np.ndarray:
        """Per ping, the expected number of fish inside the counting volume given the counted
        detections' located elevations and their σ (``count.volume_edge: soft``,
        :mod:`processing.detection.volume_edge`), shape (n_pings,) float."""
        from processing.detection.volume_edge import baseline_of, elevation_sd_rad, soft_weights
        table, n = detected.table, len(self.ping_index)
        baseline = baseline_of(self.record)
        if baseline is None or not detected.n:
            return np.bincount(table["ping"][table["in_volume"] & counted], minlength=n).astype(float)
        pos = np.stack([table[f"{a}_m"] for a in "xyz"], -1)
        sd = elevation_sd_rad(table["snr_db"], table["azimuth_rad"], table["elevation_rad"],
                              baseline_m=baseline, wavelength_m=self.record.wavelength_m,
                              interference_db=self.settings.count.edge_interference_db)
        w = soft_weights(detected.volume, pos, sd)
        w = np.where(counted, w, 0.0)
        return np.bincount(table["ping"], weights=w, minlength=n)

    def sidelobes(self, detected: Detected) -> np.ndarray:
        """Which detections the count takes for a stronger one's sidelobe or ghost
        (``count.sidelobe_db``, ``count.ghost_db``; :mod:`processing.detection.sidelobes`),
        shape (n_detections,) bool."""
        from processing.detection.sidelobes import counted_sidelobes
        st = self.settings
        if (st.count.sidelobe_db <= 0 and st.count.ghost_db <= 0) or detected.n < 2:
            return np.zeros(detected.n, bool)
        return counted_sidelobes(detected.table, self.record, st.count,
                                 range_resolution_m=detected.range_resolution_m,
                                 azimuth_resolution_rad=detected.azimuth_resolution_rad,
                                 image_group=st.detect.image_group)

    def _target_strength(self, detected: Detected, *, near_field: bool):
        """TS_uncomp, TS_comp and the two-way pattern (dB) of every detection (NaN without a
        calibration or the element geometry)."""
        from processing.backscatter.calibration import calibration_of
        from processing.backscatter.target_strength import beam_pattern_of, target_strength_db
        st, det, n = self.settings, detected.table, detected.n
        sonar_xyz = np.stack([det[f"{a}_m"] for a in "xyz"], -1).reshape(n, 3)
        try:     # recorded data may lack a calibration or the element geometry: TS is then NaN
            cal = calibration_of(self.tree)
            return target_strength_db(det["amplitude"], det["range_m"], sonar_xyz,
                                      gain_counts_m=cal.gain_counts_m,
                                      absorption_db_per_m=cal.absorption_db_per_m,
                                      pattern=beam_pattern_of(self.tree, st.detect.image_group,
                                                              st.image.spatial_window),
                                      near_field=near_field)
        except DatasetError:
            return np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)

    def single_targets(self, detected: Detected) -> dict:
        """Target strength and the tracker's single-target verdict of every detection (the
        sidelobe rule and ``track.min_ts_db``; the echosounder criteria are
        :meth:`target_detection`).

        Returns
        -------
        dict of ndarray, each shape (n_detections,)
            ``ts_uncomp_db``, ``ts_comp_db`` (dB re 1 m²; NaN without a calibration, ts_comp NaN
            beyond the compensable beam), ``beam_pattern_db`` (two-way, dB re axis) and
            ``single_target`` (bool); see :mod:`processing.backscatter.single_targets`.
        """
        from processing.backscatter.single_targets import single_targets
        st, det = self.settings, detected.table
        ts_u, ts_c, pat = self._target_strength(detected, near_field=st.single_target.near_field)
        single = single_targets(det["ping"], det["range_m"], det["azimuth_rad"], det["amplitude"],
                                range_resolution_m=detected.range_resolution_m,
                                azimuth_resolution_rad=detected.azimuth_resolution_rad,
                                sidelobe_db=st.track.sidelobe_db)
        single &= ~(ts_c < st.track.min_ts_db)
        return {"ts_uncomp_db": ts_u, "ts_comp_db": ts_c, "beam_pattern_db": pat,
                "single_target": single}

    @cached_property
    def nominal_echo_length_m(self) -> float:
        """Echo length (m) of one point target at the −level_db points of the matched-filter
        envelope: the normaliser of echo lengths (:mod:`processing.backscatter.echo_criteria`)."""
        from processing.backscatter.echo_criteria import nominal_echo_length_m
        from processing.imaging.compression import RangeFilter
        rec, st = self.record, self.settings
        rf = RangeFilter.design(rec.replica, n_samples=rec.samples.shape[-1], rate_hz=rec.rate_hz,
                                bandwidth_hz=rec.bandwidth_hz, range_window=st.image.range_window)
        return nominal_echo_length_m(rf.response, rf.rate_hz, rec.sound_speed_m_s,
                                     level_db=st.single_target.echo_length_level_db)

    @cached_property
    def moving_echo_range_phase_deg(self) -> float:
        """The range phase deviation (deg) of one point echo of a target closing at
        ``single_target.maximum_radial_speed_m_s``: what the range phase rule's limit allows
        for motion (:func:`processing.backscatter.echo_criteria.moving_echo_range_phase_deg`)."""
        from processing.backscatter.echo_criteria import moving_echo_range_phase_deg
        from processing.imaging.compression import RangeFilter
        rec, st = self.record, self.settings
        v = st.single_target.maximum_radial_speed_m_s
        if not v > 0:
            return 0.0
        rf = RangeFilter.design(rec.replica, n_samples=rec.samples.shape[-1], rate_hz=rec.rate_hz,
                                bandwidth_hz=rec.bandwidth_hz, range_window=st.image.range_window)
        f_d = 2.0 * v * rec.center_frequency_hz / rec.sound_speed_m_s
        return moving_echo_range_phase_deg(rec.replica, rf.spectrum, rf.rate_hz, f_d,
                                           level_db=st.single_target.echo_length_level_db)

    def target_detection(self, detected: Detected | None = None, *, chunk: int = 8) -> dict:
        """Single-target detection by the echosounder criteria
        (:mod:`processing.backscatter.echo_criteria`, ``single_target`` settings): every
        detection is a candidate, measured in the images of its beam (imaged again, ``chunk``
        pings at a time, unless ``detected`` kept them).

        Returns
        -------
        dict of ndarray, each shape (n_detections,)
            ``ts_uncomp_db``, ``ts_comp_db`` (dB re 1 m²), ``beam_pattern_db`` (two-way at the
            located position, near field included when ``single_target.near_field``, dB),
            ``beam_compensation_db`` (one-way, dB), ``echo_length_m``, ``echo_length``
            (normalised), ``phase_deviation_deg`` (ψ_AB, electrical), ``angle_deviation_deg``
            (elevation, mechanical), ``azimuth_phase_deviation_deg`` (split-aperture phase,
            electrical), ``azimuth_deviation_deg`` (mechanical), ``range_phase_deviation_deg``
            (the echo's phase along range), the limits each was held to
            (``phase_deviation_limit_deg``, ``azimuth_phase_deviation_limit_deg``,
            ``range_phase_deviation_limit_deg``: the fixed limit widened by the noise's share,
            ``single_target.phase_deviation_sigmas``), the noise's share of each
            (``phase_deviation_noise_deg``, ``azimuth_phase_deviation_noise_deg``,
            ``range_phase_deviation_noise_deg``: the spread noise alone gives one echo there, NaN
            without a noise level), ``echo_spacing`` (nominal pulse lengths, inf alone),
            ``rejected_by`` (str: the first rule failed, "" for a single target) and
            ``single_target`` (bool).
        """
        from processing.backscatter.echo_criteria import echo_spacing, phase_limit_deg, verdicts
        from processing.backscatter.single_targets import single_targets
        st = self.settings
        sts = st.single_target
        detected = self.detected() if detected is None else detected
        det, n = detected.table, detected.n
        ts_u, ts_c, pat = self._target_strength(detected, near_field=sts.near_field)
        sidelobe = ~single_targets(det["ping"], det["range_m"], det["azimuth_rad"], det["amplitude"],
                                   range_resolution_m=detected.range_resolution_m,
                                   azimuth_resolution_rad=detected.azimuth_resolution_rad,
                                   sidelobe_db=sts.sidelobe_db, same_cell=False)
        length_m = np.full(n, np.nan)
        phase_dev = np.full(n, np.nan)
        angle_dev = np.full(n, np.nan)
        az_phase_dev = np.full(n, np.nan)
        az_dev = np.full(n, np.nan)
        range_dev = np.full(n, np.nan)
        # the noise's share of each phase measure (ψ_AB, split phase, range phase), deg
        noise = np.full((3, n), np.nan)
        ping = np.asarray(det["ping"], int)
        pings = np.unique(ping)
        for s in range(0, pings.size, chunk):
            part = pings[s:s + chunk]
            im = (detected.images.pings(part) if detected.images is not None
                  else self.images(pings=part))
            self._measure_echoes(im, part, ping, det, length_m, phase_dev, angle_dev, az_phase_dev, az_dev,
                                 range_dev, noise)
        nominal = self.nominal_echo_length_m
        comp = np.where(np.isfinite(pat), -0.5 * pat, np.nan)
        spacing = echo_spacing(ping, det["range_m"], det["azimuth_rad"], ~sidelobe,
                               azimuth_resolution_rad=detected.azimuth_resolution_rad) / nominal
        echo_length = length_m / nominal
        # both planes' phase deviations against the one limit, as a split-beam echosounder
        # applies it to both, each widened by its own noise (a plane without a phase, NaN, is
        # not tested)
        both = np.stack([phase_dev, az_phase_dev])
        motion = (self.moving_echo_range_phase_deg if sts.maximum_range_phase_deviation is not None
                  and np.isfinite(range_dev).any() else 0.0)
        rule = verdicts(sidelobe=sidelobe, ts_comp_db=ts_c, echo_length=echo_length,
                        phase_deviation_deg=both, phase_noise_deg=noise[:2], compensation_db=comp,
                        spacing=spacing, range_phase_deviation_deg=range_dev,
                        range_phase_noise_deg=noise[2], settings=sts,
                        range_phase_motion_deg=motion)
        limits = [phase_limit_deg(lim, nz, sts.phase_deviation_sigmas, d) for lim, nz, d in
                  ((sts.maximum_phase_deviation, noise[0], 0.0), (sts.maximum_phase_deviation, noise[1], 0.0),
                   (sts.maximum_range_phase_deviation, noise[2], motion))]
        return {"ts_uncomp_db": ts_u, "ts_comp_db": ts_c, "beam_pattern_db": pat,
                "beam_compensation_db": comp, "echo_length_m": length_m, "echo_length": echo_length,
                "phase_deviation_deg": phase_dev, "angle_deviation_deg": angle_dev,
                "azimuth_phase_deviation_deg": az_phase_dev, "azimuth_deviation_deg": az_dev,
                "range_phase_deviation_deg": range_dev,
                "phase_deviation_noise_deg": noise[0], "azimuth_phase_deviation_noise_deg": noise[1],
                "range_phase_deviation_noise_deg": noise[2],
                "phase_deviation_limit_deg": np.where(np.isnan(phase_dev), np.nan, limits[0]),
                "azimuth_phase_deviation_limit_deg": np.where(np.isnan(az_phase_dev), np.nan, limits[1]),
                "range_phase_deviation_limit_deg": np.where(np.isnan(range_dev), np.nan, limits[2]),
                "echo_spacing": spacing, "rejected_by": rule, "single_target": rule == ""}

    def _measure_echoes(self, im, part, ping, det, length_m, phase_dev, angle_dev, az_phase_dev, az_dev,
                        range_dev, noise):
        """Echo length, phase deviations and the noise's share of them (``noise``: ψ_AB, split
        phase, range phase) of the detections of pings ``part`` (rows of the file) from their
        images ``im`` (one per ping of ``part``), written in place."""
        from processing.backscatter.echo_criteria import echo_shape, split_phase_noise_gain
        from processing.imaging.compression import window
        sts = self.settings.single_target
        gi = im.group_index(self.settings.detect.image_group)
        inter = im.interferometric
        if inter:
            ia, ib = im.groups.index("A"), im.groups.index("B")
            b = im.baseline_m
        r_axis = np.asarray(im.range_m, float)
        step = float((r_axis[-1] - r_axis[0]) / (r_axis.size - 1)) if r_axis.size > 1 else 0.0
        u_beam = np.sin(np.asarray(im.beam_angle_rad, float))
        nb = u_beam.size
        # the split aperture: the two halves of the imaged subarray, their centres half the
        # aperture apart (x extent of the image's elements)
        idx = self.record.image_groups[im.groups[gi]]
        xs = np.sort(self.record.element_position_m[idx, 0])
        d_split = float(xs[-1] - xs[0]) * xs.size / (2.0 * max(xs.size - 1, 1))
        k = 2 * np.pi / im.wavelength_m
        x_el = self.record.element_position_m[idx, 0]
        g_split = (split_phase_noise_gain(x_el, window(self.settings.image.spatial_window, x_el.size),
                                          float(np.median(np.diff(u_beam))), im.wavelength_m, d_split)
                   if nb > 1 else np.nan)
        # the image noise's Rayleigh scale behind each detection (NaN: no noise level)
        sigma = (np.asarray(det["amplitude"], float) * 10.0 ** (-np.asarray(det["snr_db"], float) / 20.0)
                 if "snr_db" in det else np.full(ping.size, np.nan))
        groups = [gi] + ([ib if gi == ia else ia] if inter else [])
        for j, p in enumerate(part):
            for i in np.flatnonzero(ping == p):
                row = int(np.clip(np.rint((det["range_m"][i] - r_axis[0]) / step) if step else 0,
                                  0, r_axis.size - 1))
                beam = int(np.argmin(np.abs(u_beam - np.sin(det["azimuth_rad"][i]))))
                env = np.abs(im.image[j, gi, :, beam])
                cross = (im.image[j, ia, :, beam] * np.conj(im.image[j, ib, :, beam]) if inter else None)
                sides = (np.abs(im.image[j, gi, :, [beam - 1, beam + 1]]).T if 0 < beam < nb - 1 else None)
                shape = echo_shape(
                    env, row, range_step_m=step, level_db=sts.echo_length_level_db, cross=cross,
                    neighbours=sides, profiles=im.image[j, groups, :, beam].T, noise_sigma=sigma[i])
                length_m[i], phase_dev[i], off_sd = shape[:3]
                range_dev[i] = shape.range_phase_deviation_deg
                noise[:, i] = (shape.noise_phase_ab_deg, g_split * shape.noise_phase_deg,
                               shape.noise_phase_deg)
                if np.isfinite(off_sd):
                    du = 0.5 * (u_beam[beam + 1] - u_beam[beam - 1])
                    az_phase_dev[i] = np.degrees(k * d_split * du * off_sd)
                    az_dev[i] = np.degrees(du * off_sd / max(np.cos(im.beam_angle_rad[beam]), 1e-6))
                if inter and np.isfinite(phase_dev[i]):
                    # dφ/dψ = λ / (2π R cos(φ + γ)), R the baseline's share that elevation changes
                    th = float(im.beam_angle_rad[beam])
                    a = b[0] * np.sin(th) + b[2] * np.cos(th)
                    big_r = float(np.hypot(a, b[1]))
                    phi = float(det["elevation_rad"][i]) if "elevation_rad" in det else 0.0
                    gamma = float(np.arctan2(a, b[1]))
                    cosv = max(abs(np.cos(phi + gamma)), 1e-6)
                    angle_dev[i] = phase_dev[i] * im.wavelength_m / (2 * np.pi * big_r * cosv)
