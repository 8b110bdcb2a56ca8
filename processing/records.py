"""The public entry points over datasets: each runs the chain in memory
(:class:`processing.pipeline.RecordChain`) and writes its products into a copy of the tree
(the /Processing group), or reads them back from one (``images_of``, ``detections_of``, ...).

``processing.image(tree, settings)`` returns a new tree with /Processing holding the complex
images per image group, the interferometric phase and elevation, the settings used and the
filters' gains. Settings come, in order of preference, from the ``settings`` argument (a
:class:`~processing.settings.ProcessingSettings`, its ``image`` part, a dict, or a YAML file),
from the ``processing`` section of the scene recorded in /Provenance, or the defaults.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.atomic import staged
from processing.base.config import dump_yaml, parse_yaml, validate_file
from processing.base.dataset import (ELEMENT_GROUP, DatasetError, complex_of, read_record, source_of,
                                     split_complex)
from processing.chain import record_pings
from processing.imaging.images import Images, form_images
from processing.base.contract import COUNTS_GROUP, DETECTIONS_GROUP, PROCESSING_GROUP
from processing.base.dataset import has_group
from processing.pipeline import AFTER_KEYS, noise_band_of, resolve_settings, volume_of
from processing.settings import ImageSettings, ProcessingSettings

__all__ = ["PROCESSING_GROUP", "resolve_settings", "image", "images_of", "figure_images", "detect", "count",
           "volume_of", "detections_of", "counts_of", "write_csv", "count_summary", "format_counts",
           "with_detections", "noise_band_of"]



#: what ``image``/``count`` may store of the images: nothing, the images at the data's own
#: range sampling (every U-th row of a U-times interpolated image), or every interpolated row
IMAGE_STORAGE = ("none", "native", "full")


def _processing_attrs(im: Images, settings: ProcessingSettings) -> dict:
    """What /Processing records of how the images were made (with or without the images)."""
    return {"settings_yaml": dump_yaml(settings.model_dump(mode="json", by_alias=True)),
            "image_noise_power_gain": im.noise_power_gain, "image_signal_gain": 1.0,
            "range_resolution_m": im.range_resolution_m,
            "azimuth_resolution_rad": im.azimuth_resolution_rad,
            "interpolation": int(settings.image.interpolation),
            "image_range_m": [float(im.range_m[0]), float(im.range_m[-1])],
            "image_groups": ",".join(im.groups), "interferometric": int(im.interferometric),
            "wavelength_m": float(im.wavelength_m),
            "phase_centers_json": json.dumps({g: list(map(float, c)) for g, c in im.phase_centers_m.items()})}


def images_dataset(im: Images, ping_time, settings: ProcessingSettings, *, storage: str = "full") -> xr.Dataset:
    """/Processing of an :class:`Images`: the attributes, and the images as ``storage`` says.

    Parameters
    ----------
    im : Images
    ping_time : ndarray, shape (n_pings,)
    settings : ProcessingSettings
    storage : {"none", "native", "full"}
        ``native`` keeps every U-th row (U the interpolation factor): the images at the data's
        own range sampling, from which the interpolated rows follow by band-limited
        interpolation. The interferometric phase and the elevation are functions of the two
        images and are never stored (:class:`~processing.imaging.images.Images` derives them).
    """
    if storage not in IMAGE_STORAGE:
        raise ValueError(f"image storage must be one of {IMAGE_STORAGE}, got {storage!r}")
    attrs = _processing_attrs(im, settings)
    if storage == "none":
        return xr.Dataset(attrs=attrs)
    rows = slice(None, None, im.interpolation if storage == "native" else 1)
    dims = ("ping_time", "image_group", "image_range", "beam")
    attrs["image_storage"] = storage
    return xr.Dataset(
        {**split_complex("image", im.image[:, :, rows], dims, {"units": "ADC counts",
                                                               "long_name": "calibrated complex image I(r, θ): echo amplitude at one element"})},
        coords={"ping_time": ping_time, "image_group": list(im.groups),
                "image_range": ("image_range", im.range_m[rows], {"units": "m", "long_name": "c t / 2"}),
                "image_time": ("image_range", im.time_s[rows], {"units": "s", "long_name": "two-way delay"}),
                "beam": np.arange(im.beam_angle_rad.size),
                "beam_angle": ("beam", im.beam_angle_rad, {"units": "rad", "long_name": "azimuth θ of the beam axis"})},
        attrs=attrs)


def _record(tree):
    return read_record(tree, source=source_of(tree))


def image(tree: xr.DataTree, settings=None, *, storage: str = "full", labels: bool = False) -> xr.DataTree:
    """Images of every ping (thesis chapter 4), stored in /Processing.

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset following the data contract (simulated or recorded).
    settings : ProcessingSettings, ImageSettings, dict or path, optional
    storage : {"full", "native", "none"}
        Every interpolated row (default), every U-th row (the data's own range sampling: U
        times smaller), or only the attributes. The interferometric phase and elevation are
        derived from the two images (:func:`images_of`).
    labels : bool
        Also write /Processing/Labels: per cell the dominant contributor, its share of the
        energy and its class (processing/imaging/labels.py), from the dataset's
        /Vendor_specific/Arrivals (``abacus simulate --arrivals``).

    Returns
    -------
    xarray.DataTree
        A copy of ``tree`` with /Processing added (replaced if present).

    Raises
    ------
    processing.base.dataset.DatasetError
        The dataset lacks what imaging needs (named in the message).

    Examples
    --------
    >>> tree = processing.image(processing.open_tree("two.nc"))          # doctest: +SKIP
    >>> im = processing.images_of(tree)                                   # doctest: +SKIP
    >>> im.image.shape        # (pings, image groups A/B, range cells, beams)  # doctest: +SKIP
    (1, 2, 2276, 32)
    """
    from processing.base.dataset import as_tree
    tree = as_tree(tree)
    st = resolve_settings(tree, settings)
    rec = _record(tree)
    try:
        im = form_images(rec, st.image, noise_band_hz=noise_band_of(tree))
    except ValueError as exc:
        raise DatasetError(str(exc)) from None
    out = tree.copy()
    ping_time = tree[ELEMENT_GROUP].ds["ping_time"].values
    out[PROCESSING_GROUP] = xr.DataTree(images_dataset(im, ping_time, st, storage=storage))
    if labels:
        from processing.base.contract import LABELS_GROUP
        from processing.imaging.labels import labels_dataset
        out[LABELS_GROUP] = xr.DataTree(labels_dataset(tree, im, rec, st))
    return out


def images_of(tree: xr.DataTree) -> Images:
    """The images stored in /Processing (the same :class:`~processing.imaging.images.Images` that
    :func:`processing.imaging.images.form_images` returns; at the data's own range sampling when they
    were stored ``native``).

    Raises
    ------
    DatasetError
        No images in the dataset (run :func:`image`, or ``abacus run --images native``).
    """
    if PROCESSING_GROUP not in tree.children:
        raise DatasetError("the dataset has no /Processing group: run processing.image first")
    ds = tree[PROCESSING_GROUP].ds
    if "image_r" not in ds:
        raise DatasetError("the dataset stores no images (they were not kept): run "
                           "processing.image, or `abacus run --images native`")
    settings = ImageSettings()
    if "settings_yaml" in ds.attrs:
        data, _ = parse_yaml(str(ds.attrs["settings_yaml"]), source="/Processing settings_yaml")
        section = data.get("image", {}) if isinstance(data, dict) else {}
        settings = validate_file(ImageSettings, section, file="/Processing settings_yaml (image)")
    if ds.attrs.get("image_storage") == "native":
        settings = settings.model_copy(update={"interpolation": 1})
    groups = tuple(str(g) for g in ds["image_group"].values)
    centers = {k: np.asarray(v) for k, v in json.loads(ds.attrs.get("phase_centers_json", "{}")).items()}
    return Images(
        image=complex_of(ds, "image"), groups=groups,
        range_m=ds["image_range"].values, time_s=ds["image_time"].values,
        beam_angle_rad=ds["beam_angle"].values,
        noise_power_gain=float(ds.attrs.get("image_noise_power_gain", 1.0)),
        settings=settings, phase_centers_m=centers,
        range_resolution_m=float(ds.attrs.get("range_resolution_m", 0.0)),
        azimuth_resolution_rad=float(ds.attrs.get("azimuth_resolution_rad", 0.0)),
        wavelength_m=float(ds.attrs.get("wavelength_m", np.nan)),
        interferometric=bool(ds.attrs.get("interferometric", {"A", "B"} <= set(groups))))


# ---------------------------------------------------------------- detect, count
def figure_images(tree: xr.DataTree, pings, settings=None) -> Images:
    """The images of a few pings (file indices), for figures: the stored ones when the dataset
    keeps every interpolated row, else formed again from the samples with the settings the
    detections used (or ``settings``).

    Returns
    -------
    Images
        ``image`` has shape (len(pings), n_groups, n_range, n_beams), in the order of ``pings``.
    """
    idx = np.asarray(list(pings), int)
    pds = tree[PROCESSING_GROUP].ds if PROCESSING_GROUP in tree.children else None
    if pds is not None and "image_r" in pds and pds.attrs.get("image_storage", "full") == "full":
        return images_of(tree).pings(idx)
    if settings is None and pds is not None and has_group(tree, DETECTIONS_GROUP):
        text = tree[DETECTIONS_GROUP].ds.attrs.get("settings_yaml")
        if text:
            data, _ = parse_yaml(str(text), source="/Processing/Detections settings_yaml")
            settings = validate_file(ProcessingSettings, data or {},
                                     file="/Processing/Detections settings_yaml")
    st = resolve_settings(tree, settings)
    rec = _record(tree)
    return form_images(record_pings(rec, idx), st.image, noise_band_hz=noise_band_of(tree))




def detect(tree: xr.DataTree, settings=None, *, images: str = "none") -> xr.DataTree:
    """Detections with 3-D positions (thesis chapter 5).

    The images are formed from the samples with ``settings`` a few pings at a time
    (:func:`processing.chain.detect_record`), so memory stays at one chunk's images; images
    already stored in /Processing are kept in the output but not reused (they may have been made
    with other settings, or at the data's native range sampling).

    Parameters
    ----------
    tree : xarray.DataTree
    settings : ProcessingSettings, dict or path, optional
    images : {"none", "native", "full"}
        Also store the images in /Processing (see :func:`image`); by default they are not
        kept (they follow from the samples and the settings).

    Returns
    -------
    xarray.DataTree
        A copy with /Processing/Detections: one row per detection (dim ``detection``).

    Raises
    ------
    processing.detection.noise.NoiseEstimateError
        A noise-derived threshold on noise-free images.
    processing.base.dataset.DatasetError
        Missing pieces of the dataset, named.

    Examples
    --------
    >>> det = processing.detections_of(processing.detect(tree))          # doctest: +SKIP
    >>> det[["ping", "range_m", "azimuth_rad", "elevation_rad"]].to_dataframe()  # doctest: +SKIP
    """
    from processing.pipeline import RecordChain
    if images not in IMAGE_STORAGE:
        raise ValueError(f"images must be one of {IMAGE_STORAGE}, got {images!r}")
    chain = RecordChain(tree, settings)
    return with_detections(chain, chain.detect(keep_images=images != "none"), images)


def with_detections(chain, detected, images: str) -> xr.DataTree:
    """A copy of the chain's tree with /Processing (the images' attributes, or the images) and
    /Processing/Detections of ``detected``."""
    tree, st = chain.tree, chain.settings
    out = tree.copy()
    ping_time = tree[ELEMENT_GROUP].ds["ping_time"].values
    if images != "none":
        out[PROCESSING_GROUP] = xr.DataTree(images_dataset(detected.images, ping_time, st, storage=images))
    elif PROCESSING_GROUP not in out.children or "image_r" not in out[PROCESSING_GROUP].ds:
        out[PROCESSING_GROUP] = xr.DataTree(images_dataset(detected.first, ping_time[:1], st, storage="none"))
    out[DETECTIONS_GROUP] = xr.DataTree(_detections_dataset(detected.detections, st, detected.volume,
                                                            detected.first))
    return out


def _detections_dataset(det, st: ProcessingSettings, volume, images: Images) -> xr.Dataset:
    """/Processing/Detections of a :class:`~processing.detection.detect.Detections`."""
    t = det.table
    units = {"range_m": "m", "azimuth_rad": "rad", "elevation_rad": "rad", "psi_rad": "rad",
             "x_m": "m", "y_m": "m", "z_m": "m", "world_x_m": "m", "world_y_m": "m",
             "world_z_m": "m", "amplitude": "ADC counts", "threshold": "ADC counts", "snr_db": "dB"}
    data = {}
    for k, v in t.items():
        v = np.asarray(v)
        if v.dtype == bool:
            v = v.astype(np.int8)
        data[k] = xr.DataArray(v, dims="detection", attrs={"units": units[k]} if k in units else {})
    data["snr_db"].attrs["nan_means"] = "no noise level was estimated (e.g. a fixed threshold)"
    ds = xr.Dataset(data, attrs={
        "method": st.detect.method, "convention": st.detect.convention,
        "image_group": st.detect.image_group, "n_cells_tested": det.n_cells,
        "pfa_image": st.detect.pfa_image, "pfa_cell": det.pfa_cell if det.pfa_cell is not None else -1.0,
        "noise_sigma": det.noise.sigma if det.noise else -1.0,
        "noise_mu": det.noise.mu if det.noise else -1.0,
        "noise_fit": det.noise.describe() if det.noise else "none (no noise estimate was needed)",
        "notes": "; ".join(det.notes),
        "snr_db_note": "20 log10(amplitude / noise sigma); NaN where no noise level was estimated",
        "settings_yaml": dump_yaml(st.model_dump(mode="json", by_alias=True)),
        "range_resolution_m": images.range_resolution_m,
        "azimuth_resolution_rad": images.azimuth_resolution_rad,
        "counting_volume_m3": volume.volume_m3, "counting_range_m": list(volume.range_m),
        "counting_azimuth_halfwidth_rad": volume.azimuth_halfwidth_rad,
        "counting_elevation_halfwidth_rad": volume.elevation_halfwidth_rad})
    ds["threshold_per_ping"] = xr.DataArray(det.threshold_per_ping, dims="ping_time",
                                            attrs={"units": "ADC counts",
                                                   "nan_means": "inf: an empty image (no peak)"})
    return ds


def detections_of(tree: xr.DataTree) -> xr.Dataset:
    """The detections table: one row per detection (dim ``detection``), flags as booleans.

    Variables (units in each variable's attributes): ``ping`` (index in the file),
    ``ping_index``, ``row``, ``beam``, ``range_m``, ``azimuth_rad``, ``elevation_rad``,
    ``psi_rad``, sonar-frame ``x_m``/``y_m``/``z_m``, world ``world_x_m``/``world_y_m``/
    ``world_z_m``, ``amplitude`` (ADC counts), ``threshold``, ``snr_db``, ``in_span``,
    ``in_volume``, ``elevation_clipped``. ``.to_dataframe()`` gives a pandas table.

    Raises
    ------
    DatasetError
        No /Processing/Detections (run :func:`detect` first).
    """
    if not has_group(tree, DETECTIONS_GROUP):
        raise DatasetError("the dataset has no /Processing/Detections: run processing.detect first")
    ds = tree[DETECTIONS_GROUP].ds
    table = ds[[k for k in ds.data_vars if ds[k].dims == ("detection",)]]
    return table.assign({k: table[k].astype(bool) for k in ("in_span", "in_volume", "elevation_clipped")
                         if k in table})


def _columns(table: xr.Dataset) -> dict:
    """A table's columns as numpy arrays (what the scoring and plotting code indexes)."""
    return {k: table[k].values for k in table.data_vars}


def count(tree: xr.DataTree, settings=None, *, images: str = "none") -> xr.DataTree:
    """Counts and density per ping, and scores against the truth when the dataset has it;
    runs :func:`detect` first if the dataset holds no detections.

    Parameters
    ----------
    tree : xarray.DataTree
    settings : ProcessingSettings, dict or path, optional
    images : {"none", "native", "full"}
        Passed to :func:`detect` when the detections are made here.

    Returns
    -------
    xarray.DataTree
        A copy with /Processing/Counts (dim ``ping_time``): count_before, count_after,
        density_per_m3 and, with ground truth, true_in_volume, error_before, error_after,
        hits/misses/false alarms before and after interferometry, shared_cell_misses.

    Examples
    --------
    >>> tree = processing.count(acoustics.simulate(scene, pings=range(3)))  # doctest: +SKIP
    >>> processing.counts_of(tree)["count_after"].values                    # doctest: +SKIP
    array([2, 2, 2])
    """
    from processing.pipeline import RecordChain
    chain = RecordChain(tree, settings)
    tree, st = chain.tree, chain.settings
    if has_group(tree, DETECTIONS_GROUP):
        detected = chain.detected()          # the detections the dataset holds, as a record
    else:
        if images not in IMAGE_STORAGE:
            raise ValueError(f"images must be one of {IMAGE_STORAGE}, got {images!r}")
        detected = chain.detect(keep_images=images != "none")
        tree = with_detections(chain, detected, images)
    res, occupied = chain.count(detected)
    volume, layer, occupied_m3 = detected.volume, occupied["occupied_range_m"], occupied["occupied_volume_m3"]
    eg = tree[ELEMENT_GROUP].ds
    ping_index = chain.ping_index
    ds = xr.Dataset({k: xr.DataArray(v, dims="ping_time") for k, v in res.items()},
                    coords={"ping_time": eg["ping_time"].values,
                            "ping_index": ("ping_time", np.asarray(ping_index))},
                    attrs={"counting_volume_m3": volume.volume_m3, "gate_cells": st.count.gate_cells,
                           "has_truth": int("true_in_volume" in res),
                           "occupied_range_m": layer,
                           "occupied_volume_m3": occupied_m3})
    ds["density_per_m3"].attrs.update(units="m^-3", long_name="counted / counting volume: the "
                                      "density of the counting volume")
    ds["occupied_density_per_m3"].attrs.update(
        units="m^-3", long_name="counted / the part of the counting volume the run's located "
        "targets occupy in range: the density where the targets are (processing/base/counting_volume.py)",
        nan_means="fewer than 2 located targets: no occupied layer")
    if "count_expected" in ds:
        ds["count_expected"].attrs.update(long_name="expected number of fish inside the counting volume "
                                          "given the counted detections' located elevations and their "
                                          "Cramér–Rao σ (processing/detection/volume_edge.py)")
        ds.attrs["volume_edge"] = st.count.volume_edge
    if "count_corrected" in ds:
        ds["count_corrected"].attrs.update(long_name="expected number of fish behind count_after, fish "
                                           "sharing a resolution cell corrected for "
                                           "(processing/detection/coincidence.py)")
        ds.attrs["coincidence_correction"] = st.count.coincidence_correction
    for k in AFTER_KEYS:
        if k in ds:
            ds[k].attrs["nan_means"] = "no interferometry (normal or combined mode): no elevation"
    out = tree.copy()
    out[COUNTS_GROUP] = xr.DataTree(ds)
    return out


def counts_of(tree: xr.DataTree) -> xr.Dataset:
    """Counts per ping (dim ``ping_time``, coordinate ``ping_index``): ``count_before``,
    ``count_after``, ``density_per_m3`` and, with ground truth, ``true_in_volume``,
    ``error_before``/``error_after``, hits, misses and false alarms; the counting volume (m³) is
    the attribute ``counting_volume_m3``.

    Raises
    ------
    DatasetError
        No /Processing/Counts (run :func:`count` first).
    """
    if not has_group(tree, COUNTS_GROUP):
        raise DatasetError("the dataset has no /Processing/Counts: run processing.count first")
    return tree[COUNTS_GROUP].ds


def write_csv(tree: xr.DataTree, path) -> Path:
    """Write the detections table as CSV (atomically)."""
    import csv
    table = _columns(detections_of(tree))
    path = Path(path)
    keys = list(table)
    with staged(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for i in range(len(table[keys[0]]) if keys else 0):
            w.writerow([_fmt(table[k][i]) for k in keys])
    return path


def _fmt(v):
    if isinstance(v, (bool, np.bool_)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.9g}"
    return v


def count_summary(tree: xr.DataTree) -> dict:
    """Per-ping counts and the run's summary as plain Python (what ``abacus count --json``
    prints): means and standard deviations of counts, errors and density."""
    ds = counts_of(tree)
    c = {k: ds[k].values for k in ds.data_vars}
    c["ping_index"] = ds["ping_index"].values
    c["volume_m3"] = float(ds.attrs["counting_volume_m3"])
    n = len(c["ping_index"])
    per = []
    for i in range(n):
        row = {"ping_index": int(c["ping_index"][i])}
        for k, v in c.items():
            if k in ("ping_index", "volume_m3"):
                continue
            x = float(v[i])
            row[k] = None if not np.isfinite(x) else (x if k.endswith("per_m3") or k in ("count_corrected", "count_expected") else int(x))
        per.append(row)

    def stats(key):
        v = np.asarray(c[key], float)
        if not n or not np.isfinite(v).any():
            return {"mean": None, "std": None} if n else {"mean": 0.0, "std": 0.0}
        return {"mean": float(v.mean()), "std": float(v.std())}

    summary = {"pings": n, "counting_volume_m3": c["volume_m3"],
               "occupied_range_m": list(ds.attrs.get("occupied_range_m", [])),
               "occupied_volume_m3": float(ds.attrs.get("occupied_volume_m3", 0.0))}
    for key in ("count_before", "count_after", "count_expected", "count_corrected", "density_per_m3", "occupied_density_per_m3", "true_in_volume",
                "true_density_per_m3", "error_before", "error_after"):
        if key in c:
            summary[key] = stats(key)
    if "error_after" in c:
        def mean_abs(k):
            v = np.asarray(c[k], float)
            return float(np.mean(np.abs(v))) if n and np.isfinite(v).all() else None

        def total(k):
            v = np.asarray(c[k], float)
            return int(np.sum(v)) if np.isfinite(v).all() else None
        summary["mean_abs_error_before"] = mean_abs("error_before")
        summary["mean_abs_error_after"] = mean_abs("error_after")
        for k in ("hits_after", "misses_after", "false_alarms_after", "shared_cell_misses",
                  "hits_before", "misses_before", "false_alarms_before"):
            summary[f"total_{k}"] = total(k)
    det = tree[DETECTIONS_GROUP].ds.attrs
    summary["detection"] = {"method": det["method"], "convention": det["convention"],
                            "n_cells_tested": int(det["n_cells_tested"]),
                            "pfa_cell": float(det["pfa_cell"]), "noise": det["noise_fit"],
                            "threshold_median": float(np.median(tree[DETECTIONS_GROUP].ds["threshold_per_ping"].values))
                            if n else 0.0}
    return {"pings": per, "summary": summary}


def _f(v, spec: str) -> str:
    """A number in a format, or '–' where it does not exist (None)."""
    return "–" if v is None else format(v, spec)


def format_counts(result: dict) -> str:
    """Fixed-width per-ping table and summary of :func:`count_summary` ('–': no value, e.g.
    counts after interferometry of a dataset without it)."""
    per, s = result["pings"], result["summary"]
    truth = "error_after" in s
    head = f"{'ping':>5} {'before':>7} {'after':>6} {'density':>9}"
    if truth:
        head += f" {'true':>5} {'err_bef':>8} {'err_aft':>8} {'hits':>5} {'miss':>5} {'FA':>4}"
    lines = [head]
    for r in per:
        line = (f"{r['ping_index']:>5} {r['count_before']:>7} {_f(r['count_after'], '>6')} "
                f"{_f(r['density_per_m3'], '>9.4f')}")
        if truth:
            line += (f" {r['true_in_volume']:>5} {r['error_before']:>+8d} {_f(r['error_after'], '>+8d')} "
                     f"{_f(r['hits_after'], '>5')} {_f(r['misses_after'], '>5')} "
                     f"{_f(r['false_alarms_after'], '>4')}")
        lines.append(line)
    d = s["detection"]
    lines.append("")
    lines.append(f"{s['pings']} ping(s); counting volume {s['counting_volume_m3']:.2f} m³; threshold: "
                 f"{d['method']} ({d['convention']}), median {d['threshold_median']:.4g} counts, "
                 f"{d['n_cells_tested']} cells tested, P_fa,cell {d['pfa_cell']:.3g}")
    lines.append(f"noise: {d['noise']}")
    if s["count_after"]["mean"] is None:
        lines.append(f"counted per ping: {s['count_before']['mean']:.2f} in the span; no counts inside "
                     f"the volume (no interferometry, so no elevation)")
    else:
        lines.append(f"counted per ping: {s['count_after']['mean']:.2f} ± {s['count_after']['std']:.2f} "
                     f"inside the volume; {s['count_before']['mean']:.2f} in the span")
        lines.append(f"density of the counting volume: {s['density_per_m3']['mean']:.4f} ± "
                     f"{s['density_per_m3']['std']:.4f} m⁻³")
        occ = s.get("occupied_density_per_m3", {"mean": None})
        if occ["mean"] is not None:
            r = s["occupied_range_m"]
            lines.append(f"density where the targets are ({r[0]:.2f}–{r[1]:.2f} m, "
                         f"{s['occupied_volume_m3']:.2f} m³): {occ['mean']:.4f} ± {occ['std']:.4f} m⁻³")
    if truth:
        lines.append(f"truth per ping: {s['true_in_volume']['mean']:.2f} in the volume (density "
                     f"{s['true_density_per_m3']['mean']:.4f} m⁻³)")
        if s["error_after"]["mean"] is None:
            lines.append(f"count error before interferometry: {s['error_before']['mean']:+.2f} ± "
                         f"{s['error_before']['std']:.2f}; none after (no interferometry)")
        else:
            lines.append(f"count error before interferometry: {s['error_before']['mean']:+.2f} ± "
                         f"{s['error_before']['std']:.2f}; after: {s['error_after']['mean']:+.2f} ± "
                         f"{s['error_after']['std']:.2f} (mean |error| {s['mean_abs_error_after']:.2f})")
            lines.append(f"after interferometry: {s['total_hits_after']} hits, {s['total_misses_after']} "
                         f"misses ({s['total_shared_cell_misses']} sharing a resolution cell with "
                         f"another target), {s['total_false_alarms_after']} false alarms")
    return "\n".join(lines)
