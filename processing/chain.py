"""The processing chain over a whole record, a few pings at a time.

Images are the largest thing processing makes — at the thesis' settings one ping's two complex
images weigh 3 MB, a 100-ping run's 300 MB — and detection only needs a few numbers per detected
cell. :func:`detect_record` therefore forms the images of a chunk of pings, detects in them and
keeps the detections, so memory stays at one chunk's images whatever the number of pings; the
images of chosen pings (for figures) can be kept. Results are identical to processing every ping
at once: a pooled noise estimate is fitted first from exactly the cells the settings name
(imaging only the noise region's rows when the noise comes from a region).
"""
from __future__ import annotations

import os
import warnings
from dataclasses import replace

import numpy as np

from .counting import CountingVolume
from .detection import DetectionWarning, Detections, detect_all, fit_noise_cells, noise_cells
from .imaging import form_images
from .noise import NoiseEstimateError
from .settings import ProcessingSettings

__all__ = ["detect_record", "record_pings", "default_workers", "DEFAULT_CHUNK_PINGS"]

#: pings imaged at once: 8 pings of the thesis' images are ~25 MB of complex images
DEFAULT_CHUNK_PINGS = 8


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
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        n = os.cpu_count() or 1
    return max(1, min(4, n))


def _pooled_noise(record, settings: ProcessingSettings, *, noise_band_hz, chunk: int,
                  noise_magnitudes=None, workers: int = 1):
    """The pooled Rayleigh fit the detection settings ask for, or None (per-ping noise, a
    threshold that needs none). Fitted on exactly the cells a single pass over every ping
    would use."""
    st = settings.detect
    if st.noise.per_ping or not (st.needs_noise or st.noise.source != "image"):
        return None
    im_st = settings.image
    if st.noise.source == "noise_file":
        cells = [noise_magnitudes]
        n_beams = noise_magnitudes.shape[-1]
    else:
        if st.noise.source == "region":
            # only the noise region's rows: the same samples as in the full image
            lo, hi = st.noise.range_m
            if im_st.range_m is not None:
                lo, hi = max(lo, im_st.range_m[0]), min(hi, im_st.range_m[1])
            if hi > lo:
                im_st = im_st.model_copy(update={"range_m": (lo, hi)})
        def one(sl):
            im = form_images(record_pings(record, sl), im_st, noise_band_hz=noise_band_hz)
            mags = np.abs(im.image[:, im.group_index(st.image_group)])
            return noise_cells(mags, st, im.range_m, im.beam_angle_rad), im.beam_angle_rad.size

        parts = _map(one, list(_chunks(record.samples.shape[0], chunk)), workers)
        cells = [c for c, _ in parts]
        n_beams = parts[0][1]
    try:
        fit = fit_noise_cells(np.concatenate(cells), st, n_beams=n_beams,
                              upsample=im_st.interpolation)
    except NoiseEstimateError:
        if st.needs_noise:
            raise
        return None
    return fit


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
        As :func:`processing.detection.detect_all` over every ping (``ping`` indexes the record).
    kept : Images or None
        The images of ``keep_pings``, in that order (None when none were asked for).
    """
    n = record.samples.shape[0]
    chunk = max(1, int(chunk_pings))
    workers = default_workers() if workers is None else max(1, int(workers))
    st = settings.detect
    fit = _pooled_noise(record, settings, noise_band_hz=noise_band_hz, chunk=chunk,
                        noise_magnitudes=noise_magnitudes, workers=workers)
    notes = []
    if fit is not None and not fit.rayleigh_like:
        msg = (f"the noise cells are not Rayleigh-like ({fit.describe()}): the derived threshold "
               f"may not hold its false-alarm rate")
        warnings.warn(msg, DetectionWarning, stacklevel=2)
        notes.append(msg)
    keep = [int(k) for k in keep_pings]

    def one(sl):
        sub = record_pings(record, sl)
        im = form_images(sub, settings.image, noise_band_hz=noise_band_hz)
        sub_pose = pose
        if pose is not None and np.ndim(pose[1]) == 3:   # per-ping poses: this chunk's
            sub_pose = (np.asarray(pose[0])[sl], np.asarray(pose[1])[sl])
        det = detect_all(im, sub, st, volume, upsample=im.interpolation, pose=sub_pose,
                         noise_magnitudes=noise_magnitudes, noise=fit)
        det.table["ping"] = det.table["ping"] + sl.start
        kept = {k: im.pings(slice(k - sl.start, k - sl.start + 1)) for k in keep
                if sl.start <= k < sl.stop}
        return det, kept

    tables, thresholds, kept, last = [], [], {}, None
    for det, k in _map(one, list(_chunks(n, chunk)), workers):
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
