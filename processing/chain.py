"""The processing chain over a whole record, a few pings at a time.

Images are the largest thing processing makes — at the thesis' settings one ping's two complex
images weigh 3 MB, a 100-ping run's 300 MB — and detection only needs a few numbers per detected
cell. :func:`detect_record` therefore forms the images of a chunk of pings, detects in them and
keeps the detections, so memory stays at one chunk's images whatever the number of pings; the
images of chosen pings (for figures) can be kept. Results are identical to processing every ping
at once, also when one noise level is pooled over every ping (the thesis' setting).

A pooled noise level is known only once every ping is imaged, yet each ping is imaged only once:
each chunk keeps its noise cells and describes its peaks above a lower bound of the final
threshold (its own noise fit with σ halved); once the pooled fit of all the cells is known, the
final threshold picks the detections out of each chunk's candidates — exactly those it would
detect, since whether a cell is a local maximum does not depend on the threshold. A chunk whose
bound turns out above the final threshold (noise far from stationary) is imaged again.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from processing.base.counting_volume import CountingVolume
from processing.detection.detect import (DetectionWarning, Detections, Thresholds, candidates, detect_all,
                        fit_noise_cells, noise_cells, ping_thresholds, refit_elevations, select, snr_db)
from processing.imaging.images import form_images
from processing.detection.noise import NoiseEstimateError, RayleighFit, rayleigh_mean
from processing.base.resources import usable_cores
from processing.settings import ProcessingSettings

__all__ = ["detect_record", "record_pings", "default_workers", "DEFAULT_CHUNK_PINGS", "chain_memory_terms"]

#: pings imaged at once: 4 pings of the thesis' images are ~13 MB of complex images, ~20 MB with
#: their magnitudes, per thread (measured on the default scene: processing peaks 78 MB above the
#: samples with 4, 114 MB with 8, in the same time)
DEFAULT_CHUNK_PINGS = 4

#: a chunk's candidate peaks are those above the threshold of its own noise fit with σ scaled by
#: this (0.5: 6 dB below); the pooled σ falls below that only if the noise level changes by more
#: than a factor 2 across the record, and that chunk is then imaged again
BOUND_SIGMA_FACTOR = 0.5


def record_pings(record, index):
    """The record restricted to some pings (``index``: a slice — samples not copied — or an
    index array)."""
    return replace(record, samples=record.samples[index], ping_index=record.ping_index[index])


def _chunks(n: int, size: int):
    for p0 in range(0, n, size):
        yield slice(p0, min(n, p0 + size))


def _map(fn, items, workers: int):
    """``[fn(x) for x in items]``, on ``workers`` threads when there is more than one item (the
    FFTs and array maths release the GIL); the order of the results is the order of ``items``,
    so results do not depend on the number of threads."""
    if workers <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(max_workers=min(workers, len(items))) as pool:
        return list(pool.map(fn, items))


def default_workers() -> int:
    """Threads for the chain: the cores this process may use (at most 4: memory is one chunk's
    images per thread)."""
    return min(4, usable_cores())


#: pings per chunk assumed by the memory bound (twice the default: a caller may ask for more)
_BOUND_CHUNK_PINGS = 8


def chain_memory_terms(settings: ProcessingSettings, *, pings: int, channels: int, samples: int,
                       pulse_samples: float, sample_spacing_m: float, groups: int,
                       images: str = "none") -> list:
    """What the chain holds at once, as ``(name, bytes)`` terms for a resource estimate
    (an upper bound: computed before anything is allocated).

    Parameters
    ----------
    settings : ProcessingSettings
    pings, channels, samples : int
        The record's shape: pings x receive elements x samples per ping.
    pulse_samples : float
        The transmit pulse's length in samples.
    sample_spacing_m : float
        Range between samples, c / (2 fs) (m).
    groups : int
        Images per ping (2 in interferometric mode, else 1).
    images : {"none", "native", "full"}
        Whether the images are stored too.

    Returns
    -------
    list of (str, float)
        ``"processing"``: per thread (at most :func:`default_workers`) a chunk of pings of
        compressed spectra, interpolated channels and complex images; ``"stored images"`` when
        kept.
    """
    im = settings.image
    rows = samples * im.interpolation
    if im.range_m is not None:   # only the image's range window is kept
        rows = min(rows, int((im.range_m[1] - im.range_m[0]) / sample_spacing_m * im.interpolation) + 2)
    beams = im.n_beams or 64
    nfft = 1.1 * (samples + pulse_samples)
    chunk = min(_BOUND_CHUNK_PINGS, pings)
    per_thread = chunk * (channels * nfft * (1 + im.interpolation) * 16 + groups * rows * beams * 16)
    threads = min(default_workers(), max(1, -(-pings // max(1, chunk))))
    terms = [("processing", threads * per_thread)]
    if images != "none":
        r = rows if images == "full" else samples
        terms.append(("stored images", float(pings) * groups * r * beams * 8))
    return terms


def _pools_image_noise(st) -> bool:
    """Whether the settings pool one noise fit over the images of every ping (noise from the
    images or a region of them, not per ping)."""
    return (not st.noise.per_ping and st.noise.source in ("image", "region")
            and (st.needs_noise or st.noise.source != "image"))


def _file_noise(settings: ProcessingSettings, noise_magnitudes):
    """The pooled fit of a noise-only dataset's cells (``noise.source: noise_file``), or None."""
    st = settings.detect
    if st.noise.per_ping or st.noise.source != "noise_file":
        return None
    return _pooled_fit(noise_magnitudes, st, noise_magnitudes.shape[-1],
                       settings.image.interpolation)


def _pooled_fit(cells, st, n_beams: int, upsample):
    """Rayleigh fit of the cells; None when they carry no noise and the threshold needs none."""
    try:
        return fit_noise_cells(cells, st, n_beams=n_beams, upsample=upsample)
    except NoiseEstimateError:
        if st.needs_noise:
            raise
        return None


def _chunk_pose(pose, sl):
    """The pose of a chunk's pings (a fixed pose is every ping's)."""
    if pose is not None and np.ndim(pose[1]) == 3:
        return np.asarray(pose[0])[sl], np.asarray(pose[1])[sl]
    return pose


def _kept(im, sl, keep):
    """Copies of the images of the chosen pings in this chunk (a view would keep the chunk's)."""
    return {k: replace(im, image=im.image[k - sl.start:k - sl.start + 1].copy()) for k in keep
            if sl.start <= k < sl.stop}


def _detect_chunk(record, settings: ProcessingSettings, volume, sl, *, fit, noise_band_hz, pose,
                  noise_magnitudes, keep):
    """Image a chunk and detect in it with a known pooled fit (or none): the chain's plain path."""
    sub = record_pings(record, sl)
    im = form_images(sub, settings.image, noise_band_hz=noise_band_hz)
    det = detect_all(im, sub, settings.detect, volume, upsample=im.interpolation,
                     pose=_chunk_pose(pose, sl), noise_magnitudes=noise_magnitudes, noise=fit)
    det.table["ping"] = det.table["ping"] + sl.start
    return det, _kept(im, sl, keep)


def _refit_chunk(record, settings: ProcessingSettings, volume, sl, det: Detections, *, noise_band_hz, pose):
    """``detect.elevation: fit`` for a chunk's pooled detections (rows of ``det.table``, whose
    ``ping`` indexes the record): the chunk imaged again and the fit written in place."""
    if not len(det.table.get("ping", ())):
        return
    im = form_images(record_pings(record, sl), settings.image, noise_band_hz=noise_band_hz)
    refit_elevations(det.table, im, record, volume, pose=pose, ping_offset=sl.start)


@dataclass
class _Pool:
    """What one imaging pass keeps of a chunk while the pooled noise fit is not yet known.

    ``cells``: its noise cells; ``thresholds``: those of its own noise fit (σ scaled by
    :data:`BOUND_SIGMA_FACTOR` where the threshold depends on σ) and ``table`` the candidates
    above them, or, where the threshold does not depend on σ, the final detections (only their
    SNR awaits the pooled σ); ``table`` is None when the chunk had no noise of its own to bound
    the threshold with.
    """

    sl: slice
    cells: np.ndarray
    n_beams: int
    table: dict | None
    thresholds: Thresholds | None
    kept: dict


def _pool_chunk(record, settings: ProcessingSettings, volume, sl, *, noise_band_hz, pose, keep):
    """Image a chunk once: its noise cells and its candidate peaks (:class:`_Pool`)."""
    st = settings.detect
    sub = record_pings(record, sl)
    im = form_images(sub, settings.image, noise_band_hz=noise_band_hz)
    mags = np.abs(im.image[:, im.group_index(st.image_group)])
    cells = noise_cells(mags, st, im.range_m, im.beam_angle_rad)
    n_beams = im.beam_angle_rad.size
    try:
        own = fit_noise_cells(cells, st, n_beams=n_beams, upsample=im.interpolation)
    except NoiseEstimateError:
        own = None
    if own is None and st.needs_noise:
        return _Pool(sl, cells, n_beams, None, None, _kept(im, sl, keep))
    if st.needs_noise:
        sigma = own.sigma * BOUND_SIGMA_FACTOR
        own = replace(own, sigma=sigma, mu=rayleigh_mean(sigma))
    thr = ping_thresholds(mags, st, im.range_m, im.beam_angle_rad, volume,
                          upsample=im.interpolation, noise=own)
    table = candidates(im, sub, st, thr.per_ping, volume, pose=_chunk_pose(pose, sl),
                       magnitudes=mags)
    if not st.needs_noise:
        # final already (the threshold ignores σ): select now, and keep no per-cell (CFAR)
        # thresholds, which weigh as much as an image (the scalar summaries stay)
        table = select(table, thr)
        thr = replace(thr, per_ping=[])
    return _Pool(sl, cells, n_beams, table, thr, _kept(im, sl, keep))


def _from_pool(part: _Pool, fit: RayleighFit | None, st):
    """A chunk's detections from its pool and the pooled fit, or None where the pool cannot
    give them exactly (no bound, or the bound lies above the final threshold)."""
    if part.table is None:
        return None
    final = part.thresholds.with_noise(fit, st)
    if st.needs_noise:
        if not all(np.all(f >= b) for f, b in zip(final.per_ping, part.thresholds.per_ping)):
            return None
        table = select(part.table, final)
    else:
        table = dict(part.table)
        table["snr_db"] = snr_db(table["amplitude"], final.sigma[table["ping"]])
    table["ping"] = table["ping"] + part.sl.start
    return Detections(table, final.median, fit, final.pfa_cell, final.n_cells, [])


def _fit_of_parts(parts, st, upsample: int):
    """The pooled fit of every chunk's noise cells: the same cells in the same order as one
    pass over every ping, hence the same fit."""
    cells = np.concatenate([p.cells for p in parts])
    for p in parts:
        p.cells = None      # they can be every image's |I|: no second copy beyond this point
    return _pooled_fit(cells, st, parts[0].n_beams, upsample)


def _one_pass(record, settings: ProcessingSettings, volume, chunks, *, noise_band_hz, pose, keep,
              workers: int):
    """Detections of every chunk with a noise fit pooled over every ping's images, each ping
    imaged once (again only for a chunk whose pool cannot give its detections exactly).

    Returns
    -------
    fit : RayleighFit or None
    results : list of (Detections, dict of kept images), in chunk order
    """
    st = settings.detect
    parts = _map(lambda sl: _pool_chunk(record, settings, volume, sl, noise_band_hz=noise_band_hz,
                                        pose=pose, keep=keep), chunks, workers)
    if not parts:
        return _pooled_fit(np.zeros(0), st, 1, settings.image.interpolation), []
    fit = _fit_of_parts(parts, st, settings.image.interpolation)
    dets = [_from_pool(p, fit, st) if fit is not None else None for p in parts]
    if st.elevation == "fit":
        # the fit needs the images, which the pool did not keep: each such chunk imaged again
        _map(lambda pd: _refit_chunk(record, settings, volume, pd[0].sl, pd[1], noise_band_hz=noise_band_hz,
                                     pose=pose), [(p, d) for p, d in zip(parts, dets) if d is not None], workers)
    redo = [p for p, d in zip(parts, dets) if d is None]
    again = _map(lambda p: _detect_chunk(record, settings, volume, p.sl, fit=fit,
                                         noise_band_hz=noise_band_hz, pose=pose,
                                         noise_magnitudes=None, keep=())[0], redo, workers)
    redone = dict(zip((p.sl.start for p in redo), again))
    return fit, [(d if d is not None else redone[p.sl.start], p.kept) for p, d in zip(parts, dets)]


def detect_record(record, settings: ProcessingSettings, volume: CountingVolume, *,
                  noise_band_hz: float | None = None, pose=None, noise_magnitudes=None,
                  chunk_pings: int = DEFAULT_CHUNK_PINGS, keep_pings=(), workers: int | None = None):
    """Image and detect every ping of a record, a chunk of pings at a time.

    Parameters
    ----------
    record : SonarRecord
    settings : ProcessingSettings
    volume : CountingVolume
    noise_band_hz : float, optional
        Receiver noise band (for the images' noise gain).
    pose : (position_m (3,), rotation (3, 3)), optional
        Sonar pose in the world frame.
    noise_magnitudes : ndarray, optional
        |I| of a noise-only dataset (``noise.source: noise_file``).
    chunk_pings : int
        Pings imaged at once (memory: one chunk's images).
    keep_pings : iterable of int
        Indices (in the record) of pings whose images to return, e.g. for figures.
    workers : int, optional
        Threads imaging chunks side by side (default :func:`default_workers`); the result is
        the same for any number.

    Returns
    -------
    detections : Detections
        As :func:`processing.detection.detect.detect_all` over every ping (``ping`` indexes the record).
    kept : Images or None
        The images of ``keep_pings``, in that order (None when none were asked for).
    """
    n = record.samples.shape[0]
    chunks = list(_chunks(n, max(1, int(chunk_pings))))
    workers = default_workers() if workers is None else max(1, int(workers))
    st = settings.detect
    keep = [int(k) for k in keep_pings]
    if _pools_image_noise(st):
        fit, results = _one_pass(record, settings, volume, chunks, noise_band_hz=noise_band_hz,
                                 pose=pose, keep=keep, workers=workers)
    else:
        fit = _file_noise(settings, noise_magnitudes)
        results = _map(lambda sl: _detect_chunk(
            record, settings, volume, sl, fit=fit, noise_band_hz=noise_band_hz, pose=pose,
            noise_magnitudes=noise_magnitudes, keep=keep), chunks, workers)
    notes = []
    if fit is not None and not fit.rayleigh_like:
        msg = (f"the noise cells are not Rayleigh-like ({fit.describe()}): the derived threshold "
               f"may not hold its false-alarm rate")
        warnings.warn(msg, DetectionWarning, stacklevel=2)
        notes.append(msg)

    tables, thresholds, kept, last = [], [], {}, None
    for det, k in results:
        tables.append(det.table)
        thresholds.append(det.threshold_per_ping)
        notes += [m for m in det.notes if m not in notes]
        kept.update(k)
        last = det
    table = {k: np.concatenate([t[k] for t in tables]) for k in tables[0]} if tables else {}
    out = Detections(table, np.concatenate(thresholds) if thresholds else np.zeros(0),
                     fit if fit is not None else (last.noise if last is not None else None),
                     last.pfa_cell if last is not None else None,
                     last.n_cells if last is not None else 0, notes)
    images = None
    if kept:
        first = kept[keep[0]]
        images = replace(first, image=np.concatenate([kept[k].image for k in keep if k in kept]))
    return out, images
