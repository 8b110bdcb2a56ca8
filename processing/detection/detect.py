"""Detection, 3-D location and counting of every ping (thesis chapter 5 and §6.2–6.3).

For each ping, on one image (subarray A by default):

1. threshold — from the Rayleigh noise level and a false-alarm probability per image (default),
   a fixed value, a fraction of the ping's brightest cell, or a 2-D CFAR;
2. peaks — local maxima of |I| above the threshold, refined between cells;
3. elevation — from ψ_AB at the peak with the refined azimuth;
4. 3-D position — the thesis' system (processing.detection.locate), in the sonar and world frames;
5. counting — detections in the counting volume's range–azimuth span (before interferometry) and
   inside the volume (after); density = count / volume;
6. scoring — when the dataset has ground truth, matches, misses, false alarms and count errors.

Everything tested with numbers: the number of cells N tested per image counts native range samples
(the image is interpolated U times, which adds no independent cells) times the beams in the span.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from processing.base.counting_volume import CountingVolume
from processing.imaging.images import Images
from processing.imaging.interferometry import elevation_from_phase
from processing.detection.locate import locate, to_world
from processing.detection.noise import NoiseEstimateError, RayleighFit, rayleigh_fit, rayleigh_mean
from processing.detection.peaks import local_maxima, refine_peaks
from processing.detection.scoring import match
from processing.settings import DetectSettings
from processing.detection.thresholds import cell_pfa, cfar_threshold, rayleigh_threshold

__all__ = ["DetectionWarning", "Detections", "detect_all", "score_all", "n_tested_cells", "noise_cells",
           "fit_noise_cells", "noise_fit", "Thresholds", "ping_thresholds", "threshold_from_noise",
           "candidates", "select", "snr_db", "refit_elevations"]


class DetectionWarning(UserWarning):
    """Detection ran, but something about its inputs deserves a look (e.g. non-Rayleigh noise)."""


@dataclass
class Detections:
    """The detections table (one entry per detection) and what produced it.

    Attributes
    ----------
    table : dict of ndarray, each shape (n_detections,)
        ping (index in the file), ping_index, row, beam, range_m, azimuth_rad, elevation_rad,
        elevation_clipped, psi_rad, x_m, y_m, z_m (sonar frame), world_x_m, world_y_m, world_z_m,
        amplitude (image units), snr_db (NaN where no noise level exists), threshold,
        in_span (range and azimuth in the counting volume), in_volume (3-D position inside).
    threshold_per_ping : ndarray, shape (n_pings,)
        Scalar threshold of each ping (for CFAR: the median over the tested cells).
    noise : RayleighFit or None
    pfa_cell : float or None
    n_cells : int
    """

    table: dict
    threshold_per_ping: np.ndarray
    noise: RayleighFit | None
    pfa_cell: float | None
    n_cells: int
    notes: list = field(default_factory=list)


def n_tested_cells(range_m, beam_angle_rad, volume: CountingVolume, upsample: int) -> int:
    """Independent cells per image in the counting span: native range samples x beams."""
    rows = int(np.count_nonzero((range_m >= volume.range_m[0]) & (range_m <= volume.range_m[1])))
    beams = int(np.count_nonzero(np.abs(beam_angle_rad) <= volume.azimuth_halfwidth_rad))
    return max(1, int(round(rows / max(upsample, 1))) * max(beams, 1))


def noise_cells(mags, st: DetectSettings, range_m, beam_angle_rad):
    """The image cells the detection settings take the noise from.

    Parameters
    ----------
    mags : ndarray, shape (n_pings, n_range, n_beams)
        |I| (ADC counts) of the image group detected on.
    st : DetectSettings
    range_m : ndarray, shape (n_range,)
    beam_angle_rad : ndarray, shape (n_beams,)

    Returns
    -------
    ndarray, shape (n_pings, n_rows, n_cols)
        The cells of the noise region (``noise.source: region``) or all of them (``image``).
    """
    ns = st.noise
    if ns.source == "region":
        rows = (range_m >= ns.range_m[0]) & (range_m <= ns.range_m[1])
        cols = np.ones(beam_angle_rad.size, bool)
        if ns.azimuth is not None:
            cols = (beam_angle_rad >= ns.azimuth[0]) & (beam_angle_rad <= ns.azimuth[1])
        return mags[..., rows, :][..., cols]
    return mags


def fit_noise_cells(cells, st: DetectSettings, n_beams: int, upsample: int):
    """Rayleigh fit of noise cells; the KS test sees every U-th range sample and a few beams
    (cells closer than a resolution cell are correlated).

    Parameters
    ----------
    cells : ndarray, shape (n_pings, n_rows, n_cols)
    st : DetectSettings
    n_beams : int
        Beams of the image (sets the KS decimation across beams).
    upsample : int
        Range interpolation factor.

    Returns
    -------
    RayleighFit
    """
    step_b = 1 if n_beams < 8 else max(1, n_beams // 8)
    dec = (Ellipsis, slice(None, None, max(upsample, 1)), slice(None, None, step_b))
    return rayleigh_fit(cells, estimator=st.noise.estimator, decimate=dec)


def noise_fit(mags, st: DetectSettings, range_m, beam_angle_rad, upsample, noise_mags=None):
    """Rayleigh fit of the image cells the detection settings take the noise from.

    Parameters
    ----------
    mags : ndarray, shape (n_pings, n_range, n_beams)
        |I| (ADC counts) of the image group detected on.
    st : DetectSettings
    range_m : ndarray, shape (n_range,)
    beam_angle_rad : ndarray, shape (n_beams,)
    upsample : int
        Range interpolation factor (cells closer than a resolution cell are correlated).
    noise_mags : ndarray, optional
        |I| of a noise-only dataset (``noise.source: noise_file``).

    Returns
    -------
    RayleighFit
    """
    cells = noise_mags if st.noise.source == "noise_file" else noise_cells(mags, st, range_m,
                                                                           beam_angle_rad)
    return fit_noise_cells(cells, st, np.asarray(beam_angle_rad).size, upsample)


def detect_all(images: Images, record, settings: DetectSettings, volume: CountingVolume, *,
               upsample: int, pose=None, noise_magnitudes=None, noise=None) -> Detections:
    """Detections of every ping.

    Parameters
    ----------
    images : Images
        From :func:`processing.imaging.images.form_images` or :func:`processing.records.images_of`.
    record : SonarRecord
        For the geometry (phase centres, transmitter, sound speed, wavelength).
    settings : DetectSettings
    volume : CountingVolume
    upsample : int
        The images' range interpolation factor.
    pose : (position_m (3,), rotation (3, 3)), optional
        Sonar pose for world coordinates; identity if None; per ping (shapes (n_pings, 3) and
        (n_pings, 3, 3)) for a moving platform.
    noise_magnitudes : ndarray, optional
        |I| of a noise-only dataset (settings.noise.source == "noise_file").
    noise : RayleighFit, optional
        A pooled noise fit computed beforehand (e.g. over every chunk of a long run); used
        instead of fitting these images' own cells.

    Raises
    ------
    NoiseEstimateError
        A Rayleigh threshold was asked for but the images carry no noise.
    """
    g = images.group_index(settings.image_group)
    mags = np.abs(images.image[:, g])
    thr = ping_thresholds(mags, settings, images.range_m, images.beam_angle_rad, volume,
                          upsample=upsample, noise_magnitudes=noise_magnitudes, noise=noise)
    if noise is None and thr.noise is not None and not thr.noise.rayleigh_like:
        msg = (f"the noise cells are not Rayleigh-like ({thr.noise.describe()}): the derived "
               f"threshold may not hold its false-alarm rate")
        warnings.warn(msg, DetectionWarning, stacklevel=2)
        thr.notes.append(msg)
    table = select(candidates(images, record, settings, thr.per_ping, volume, pose=pose, magnitudes=mags), thr)
    if settings.elevation == "fit":
        refit_elevations(table, images, record, volume, pose=pose)
    return Detections(table, thr.median, thr.noise, thr.pfa_cell, thr.n_cells, thr.notes)


def refit_elevations(table: dict, images: Images, record, volume: CountingVolume, *, pose=None,
                     ping_offset: int = 0) -> None:
    """``detect.elevation: fit``: the two-target fit's ψ, azimuth and range where it is taken
    (:mod:`processing.detection.elevation_fit`), written into the table (in place).

    Parameters
    ----------
    table : dict of ndarray, each shape (n,)
        A selected detections table (:class:`Detections`); ``psi_rad``, ``azimuth_rad``,
        ``range_m``, ``elevation_rad``, ``elevation_clipped``, ``x_m``…``world_z_m`` (m, sonar and
        world frames), ``in_span`` and ``in_volume`` of the refitted rows are replaced.
    images : Images
        Interferometric images holding the pings ``table["ping"] − ping_offset``; nothing is
        done for other images or an empty table.
    record : SonarRecord
    volume : CountingVolume
    pose : (position_m (3,) or (n_pings, 3), rotation (3, 3) or (n_pings, 3, 3)), optional
        Indexed by ``table["ping"]`` where per ping.
    ping_offset : int
        The record ping of ``images``' first ping.
    """
    from processing.detection.elevation_fit import fit_detections, relocate
    if not images.interferometric or not len(table.get("ping", ())):
        return
    psi, az, rg, taken = fit_detections(images, record, table["ping"] - ping_offset, table["row"], table["beam"],
                                        table["range_m"], table["azimuth_rad"], table["snr_db"])
    relocate(table, np.flatnonzero(taken), psi[taken], az[taken], rg[taken], record=record, images=images,
             volume=volume, pose=pose)


@dataclass
class Thresholds:
    """The threshold of every ping under one detection setting.

    Attributes
    ----------
    per_ping : list of (float or ndarray of shape (n_range, n_beams))
        A scalar threshold, or one per cell (CFAR), for each ping (ADC counts).
    median : ndarray, shape (n_pings,)
        Scalar summary per ping (for CFAR the median over the tested cells).
    sigma : ndarray, shape (n_pings,)
        The noise scale behind each ping's threshold (NaN where none was estimated).
    noise : RayleighFit or None
    pfa_cell : float or None
    n_cells : int
    """

    per_ping: list
    median: np.ndarray
    sigma: np.ndarray
    noise: RayleighFit | None
    pfa_cell: float | None
    n_cells: int
    notes: list = field(default_factory=list)

    def floor(self, other: "Thresholds") -> "Thresholds":
        """The lower of two settings' thresholds, per ping and cell (for a shared candidate pool)."""
        return replace(self, per_ping=[np.minimum(a, b) for a, b in zip(self.per_ping, other.per_ping)])

    def with_noise(self, fit: RayleighFit | None, settings: DetectSettings) -> "Thresholds":
        """The thresholds the same images give with the pooled noise fit ``fit`` instead.

        Only the noise scale changes: thresholds derived from it (``rayleigh``, ``fixed``) are
        recomputed exactly as :func:`ping_thresholds` computes them; the others (``fixed`` in
        counts, ``fraction_of_peak``, ``cfar``) do not depend on it and are kept.

        Parameters
        ----------
        fit : RayleighFit or None
            The pooled fit (None: no noise level, σ is NaN).
        settings : DetectSettings
            The settings these thresholds were computed with; the noise must be pooled (a
            per-ping noise level is no single fit).

        Returns
        -------
        Thresholds
        """
        if settings.noise.per_ping:
            raise ValueError("a per-ping noise level cannot be replaced by one pooled fit")
        n = self.median.size
        sigma = fit.sigma if fit is not None else np.nan
        per_ping, median = self.per_ping, self.median
        if settings.method in ("rayleigh", "fixed"):
            t = threshold_from_noise(settings, sigma, self.pfa_cell)
            per_ping, median = [t] * n, np.full(n, t)
        return replace(self, per_ping=per_ping, median=median, sigma=np.full(n, sigma), noise=fit)


def ping_thresholds(mags, settings: DetectSettings, range_m, beam_angle_rad, volume: CountingVolume, *,
                    upsample: int, noise_magnitudes=None, noise=None) -> Thresholds:
    """Thresholds of every ping (thesis §5.2): from a false-alarm probability and the noise,
    fixed, a fraction of the ping's peak, or CFAR.

    Parameters
    ----------
    mags : ndarray, shape (n_pings, n_range, n_beams)
        |I| (ADC counts) of the image group detected on.
    settings : DetectSettings
    range_m : ndarray, shape (n_range,)
    beam_angle_rad : ndarray, shape (n_beams,)
    volume : CountingVolume
        Sets the number of cells tested (for the per-cell false-alarm probability).
    upsample : int
    noise_magnitudes : ndarray, optional
        |I| of a noise-only dataset (``noise.source: noise_file``).
    noise : RayleighFit, optional
        A pooled fit to use instead of fitting these images.

    Raises
    ------
    NoiseEstimateError
        A noise-derived threshold on noise-free images.
    """
    st = settings
    r, th = range_m, beam_angle_rad
    n_ping = mags.shape[0]
    n_cells = n_tested_cells(r, th, volume, upsample)
    fit = noise
    pfa = cell_pfa(st.pfa_image, n_cells, convention=st.convention) if st.method in ("rayleigh", "cfar") else None
    if fit is None and (st.needs_noise or st.noise.source != "image"):
        try:
            if not st.noise.per_ping:
                fit = noise_fit(mags, st, r, th, upsample, noise_magnitudes)
        except NoiseEstimateError:
            if st.needs_noise:
                raise
    per_ping, median, sigmas = [], np.zeros(n_ping), np.zeros(n_ping)
    for p in range(n_ping):
        m = mags[p]
        sigma_p = fit.sigma if fit is not None else np.nan
        if st.needs_noise and st.noise.per_ping:
            sigma_p = noise_fit(mags[p:p + 1], st, r, th, upsample, noise_magnitudes).sigma
        if st.method in ("rayleigh", "fixed"):
            thr = threshold_from_noise(st, sigma_p, pfa)
        elif st.method == "fraction_of_peak":
            thr = st.fraction * float(m.max()) if m.size else np.inf
        else:
            thr, _, _ = cfar_threshold(m, pfa=pfa, kind=st.cfar.kind, guard=st.cfar.guard,
                                       training=st.cfar.training, rank=st.cfar.rank)
            if not np.isfinite(thr).any():
                raise NoiseEstimateError("CFAR found no noise in any training window (a noise-free "
                                         "image): use a fixed threshold or a fraction of the peak")
        per_ping.append(thr)
        median[p] = float(np.median(thr[np.isfinite(thr)])) if np.ndim(thr) else thr
        sigmas[p] = sigma_p
    return Thresholds(per_ping, median, sigmas, fit, pfa, n_cells)


def threshold_from_noise(settings: DetectSettings, sigma: float, pfa_cell: float | None) -> float:
    """The scalar threshold of ``rayleigh`` and ``fixed`` detection (ADC counts).

    Parameters
    ----------
    settings : DetectSettings
        ``method`` rayleigh or fixed.
    sigma : float
        Rayleigh noise scale σ (ADC counts); NaN where none was estimated (fine for a fixed
        threshold in counts).
    pfa_cell : float or None
        False-alarm probability per cell (rayleigh).

    Returns
    -------
    float
        Rises with σ (proportional to it, or independent of it in counts).
    """
    if settings.method == "rayleigh":
        return rayleigh_threshold(sigma, pfa_cell, convention=settings.convention)
    if settings.method != "fixed":
        raise ValueError(f"a {settings.method!r} threshold is not a function of the noise level")
    mu = rayleigh_mean(sigma)
    return float(settings.value) * {"counts": 1.0, "noise_mean": mu,
                                    "thesis": mu / settings.thesis_noise_mean}[settings.value_units]


def candidates(images: Images, record, settings: DetectSettings, per_ping, volume: CountingVolume, *,
               pose=None, magnitudes=None) -> dict:
    """Every local maximum above a threshold, refined, located and flagged (one row each).

    Parameters
    ----------
    images : Images
    record : SonarRecord
    settings : DetectSettings
        Only ``image_group`` is used.
    per_ping : list of (float or ndarray)
        Threshold of each ping (scalar or per cell); pass the lowest of several settings to
        describe a pool that :func:`select` then filters for each.
    volume : CountingVolume
    pose : (position_m (3,), rotation (3, 3)), optional
        Or one per ping: (n_pings, 3) and (n_pings, 3, 3).
    magnitudes : ndarray, shape (n_pings, n_range, n_beams), optional
        |I| of the image group detected on (ADC counts), where the caller has it already.

    Returns
    -------
    dict of ndarray, each shape (n,)
        The detections table without ``threshold`` and ``snr_db`` (see :class:`Detections`).
    """
    g = images.group_index(settings.image_group)
    img = images.image[:, g]
    mags = np.abs(img) if magnitudes is None else magnitudes
    found = [local_maxima(mags[p], above=t) for p, t in enumerate(per_ping)]
    ping = np.concatenate([np.full(rows.size, p) for p, (rows, _) in enumerate(found)]).astype(int) \
        if found else np.zeros(0, int)
    row = np.concatenate([rows for rows, _ in found]).astype(int) if found else np.zeros(0, int)
    beam = np.concatenate([b for _, b in found]).astype(int) if found else np.zeros(0, int)
    table = _describe(images, record, img, mags, ping, row, beam, volume, pose)
    table["cell_magnitude"] = mags[ping, row, beam] if ping.size else np.zeros(0)
    return table


def select(table: dict, thresholds: Thresholds) -> dict:
    """The rows of a candidate table whose cell exceeds this setting's threshold, with their
    ``threshold`` and ``snr_db`` (exactly what detecting with this threshold alone gives:
    a local maximum's definition does not depend on the threshold)."""
    ping = table["ping"]
    thr = np.array([t[r, b] if np.ndim(t) else t for t, r, b in
                    ((thresholds.per_ping[p], r, b) for p, r, b in zip(ping, table["row"], table["beam"]))],
                   float) if ping.size else np.zeros(0)
    keep = table["cell_magnitude"] > thr
    out = {k: v[keep] for k, v in table.items() if k != "cell_magnitude"}
    out["threshold"] = thr[keep]
    out["snr_db"] = snr_db(out["amplitude"], thresholds.sigma[out["ping"]])
    return out


def snr_db(amplitude, sigma):
    """Signal-to-noise ratio of detections, 20 log10(amplitude / σ) (dB).

    Parameters
    ----------
    amplitude : ndarray, shape (n,)
        Peak amplitudes (ADC counts).
    sigma : ndarray, shape (n,)
        Rayleigh noise scale behind each detection (ADC counts; NaN: no noise level).

    Returns
    -------
    ndarray, shape (n,)
        NaN where σ is NaN.
    """
    if not np.size(amplitude):
        return np.zeros(0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return 20 * np.log10(amplitude / sigma)


def _describe(images, record, img, mags, ping, row, beam, volume, pose):
    """Refined position, elevation, 3-D location and flags of each detection."""
    r, th = images.range_m, images.beam_angle_rad
    n = ping.size
    rng = np.empty(n)
    az = np.empty(n)
    amp = np.empty(n)
    for p in np.unique(ping):
        k = ping == p
        rng[k], az[k], amp[k] = refine_peaks(mags[p], row[k], beam[k], r, th)
    out = {"ping": ping, "ping_index": np.asarray(record.ping_index)[ping] if n else np.zeros(0, int),
           "row": row, "beam": beam, "range_m": rng, "azimuth_rad": az, "amplitude": amp}
    centers = images.phase_centers_m or {}
    if images.interferometric:
        ps = images.psi_at(ping, row, beam) if n else np.zeros(0)
        el, clipped = elevation_from_phase(ps, az, images.baseline_m, record.wavelength_m)
        pos = locate(2 * rng / record.sound_speed_m_s, az, ps,
                     transmitter_m=record.transmitter_center_m, center_a_m=centers["A"],
                     center_b_m=centers["B"], sound_speed_m_s=record.sound_speed_m_s,
                     wavelength_m=record.wavelength_m)
    else:
        # no interferometry: place detections in the x–z plane (elevation unknown, shown as 0)
        ps = np.zeros(n)
        el = np.zeros(n)
        clipped = np.zeros(n, bool)
        pos = np.stack([rng * np.sin(az), np.zeros(n), rng * np.cos(az)], -1) if n else np.zeros((0, 3))
    position, rotation = pose if pose is not None else (np.zeros(3), np.eye(3))
    position, rotation = np.asarray(position, float), np.asarray(rotation, float)
    if not n:
        world = np.zeros((0, 3))
    elif rotation.ndim == 3:   # a moving platform: each detection in its own ping's pose
        world = np.einsum("nij,nj->ni", rotation[ping], pos) + position[ping]
    else:
        world = to_world(pos, position, rotation)
    out.update({"psi_rad": ps, "elevation_rad": el, "elevation_clipped": clipped,
                "x_m": pos[:, 0], "y_m": pos[:, 1], "z_m": pos[:, 2],
                "world_x_m": world[:, 0], "world_y_m": world[:, 1], "world_z_m": world[:, 2],
                "in_span": volume.in_span(rng, az),
                "in_volume": volume.contains(pos) & images.interferometric})
    return out


def score_all(table: dict, truth: dict | None, volume: CountingVolume, n_pings: int, *,
              dr: float, dtheta: float, gate: float, unresolved: float = 1.5,
              sidelobe=None) -> dict:
    """Per-ping counts, density and (with truth) scores.

    Parameters
    ----------
    table : dict
        Detections table.
    truth : dict or None
        ``ping`` (index in file) and ``position_m`` (n, 3, sonar frame) of every true target.
    sidelobe : array_like of bool, shape (n_detections,), optional
        Detections taken for a stronger one's sidelobe (:func:`processing.detection.sidelobes.psf_sidelobes`):
        neither counted nor scored. Default: none.

    Returns
    -------
    dict of ndarray, each shape (n_pings,)
        count_before, count_after, density (per m³ after interferometry); with truth also
        true_in_volume, true_in_span, error_before, error_after, hits/misses/false_alarms
        before and after, shared_cell_misses.
    """
    ping = table["ping"]
    if sidelobe is not None:
        counted = ~np.asarray(sidelobe, bool)
        table = {**table, "in_span": table["in_span"] & counted, "in_volume": table["in_volume"] & counted}
    out = {"count_before": np.bincount(ping[table["in_span"]], minlength=n_pings),
           "count_after": np.bincount(ping[table["in_volume"]], minlength=n_pings)}
    out["density_per_m3"] = out["count_after"] / volume.volume_m3
    if truth is None:
        return out
    tp = truth["position_m"]
    tr = np.linalg.norm(tp, axis=1)
    taz = np.arctan2(tp[:, 0], tp[:, 2])
    t_span = volume.in_span(tr, taz)
    t_in = volume.contains(tp)
    keys = ("true_in_volume", "true_in_span", "hits_before", "misses_before", "false_alarms_before",
            "hits_after", "misses_after", "false_alarms_after", "shared_cell_misses")
    for k in keys:
        out[k] = np.zeros(n_pings, int)
    for p in range(n_pings):
        tk = truth["ping"] == p
        dk = ping == p
        out["true_in_volume"][p] = int(t_in[tk].sum())
        out["true_in_span"][p] = int(t_span[tk].sum())
        for when, dsel, tsel in (("before", table["in_span"], t_span), ("after", table["in_volume"], t_in)):
            d = dk & dsel
            t = tk & tsel
            s = match(table["range_m"][d], table["azimuth_rad"][d], tr[t], taz[t], dr=dr,
                      dtheta=dtheta, gate=gate, unresolved=unresolved)
            out[f"hits_{when}"][p] = s.hits
            out[f"misses_{when}"][p] = s.misses
            out[f"false_alarms_{when}"][p] = s.false_alarms
            if when == "after":
                out["shared_cell_misses"][p] = s.shared_cell_misses
    out["error_before"] = out["count_before"] - out["true_in_volume"]
    out["error_after"] = out["count_after"] - out["true_in_volume"]
    out["true_density_per_m3"] = out["true_in_volume"] / volume.volume_m3
    return out
