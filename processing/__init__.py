"""abacus.processing — the inverse problem: echoes -> images -> detections -> counts.

Works from the data contract alone (:mod:`processing.base.dataset`), so it runs the same on simulated
and recorded data; it never imports ``acoustics``. Public surface (docs/api.md; imported on first
use, so ``import processing`` is cheap)::

    image(tree, settings=None) -> DataTree     # (tree: a DataTree or a file's path) pulse compression, beamforming, interferometry
    detect(tree, settings=None) -> DataTree    # thresholds, peaks, 3-D location
    count(tree, settings=None) -> DataTree     # counts, density, scores against the truth
    images_of(tree) -> Images                  # the images as arrays
    detections_of(tree) -> xarray.Dataset      # one row per detection
    counts_of(tree) -> xarray.Dataset          # one row per ping
    track(tree, settings=None) -> DataTree     # fish tracks across pings, scored against the truth
    sv(tree, settings=None, ...) -> DataTree   # calibrated Sv: MVBS grid and NASC (/Processing/Sv)
    tracks_of(tree) -> xarray.Dataset          # one row per track, and per track point
    single_targets(tree, settings=None) -> xarray.Dataset  # single-target detection by the echosounder criteria
    open_tree(path), write_tree(tree, path)    # the dataset I/O (atomic writes)
    open_record(path) -> DataTree              # any recording read and checked (.mat, SONAR-netCDF4 2.0, echopype EK60/EK80, ...)
    echopype_view(tree) -> DataTree            # the calibrated image in the EK60 convention echopype calibrates
    write_sonar_netcdf2(tree, path)            # SONAR-netCDF4 2.0 with SingleTarget and gridded Sv
    ProcessingSettings, load_settings(path)
"""
from __future__ import annotations

from processing.base.lazy import public_api

#: public name -> module that defines it
_API = {
    "image": "processing.records", "detect": "processing.records", "count": "processing.records",
    "images_of": "processing.records", "detections_of": "processing.records",
    "counts_of": "processing.records", "count_summary": "processing.records",
    "format_counts": "processing.records", "volume_of": "processing.pipeline",
    "write_csv": "processing.records", "resolve_settings": "processing.pipeline",
    "open_tree": "processing.base.dataset", "write_tree": "processing.base.dataset",
    "read_record": "processing.base.dataset", "DatasetError": "processing.base.dataset",
    "Images": "processing.imaging.images",
    "NoiseEstimateError": "processing.detection.noise",
    "ConfigError": "processing.base.config",
    "ProcessingSettings": "processing.settings", "ImageSettings": "processing.settings",
    "load_settings": "processing.settings",
    "track": "processing.tracking.tracks", "tracks_of": "processing.tracking.tracks",
    "sv": "processing.backscatter.sv", "single_targets": "processing.backscatter.target_table",
    "write_targets_csv": "processing.backscatter.target_table", "RecordChain": "processing.pipeline",
    "as_tree": "processing.base.dataset",
    "open_record": "processing.base.convert", "echopype_view": "processing.backscatter.echopype_view",
    "write_sonar_netcdf2": "processing.export",
}

__getattr__, __dir__, __all__ = public_api("processing", _API, globals(), extra=())
