"""abacus.processing — the inverse problem: echoes -> images -> detections -> counts.

Works from the data contract alone (:mod:`processing.dataset`), so it runs the same on simulated
and recorded data; it never imports ``acoustics``. Public surface (docs/api.md; imported on first
use, so ``import processing`` is cheap)::

    image(tree, settings=None) -> DataTree     # pulse compression, beamforming, interferometry
    detect(tree, settings=None) -> DataTree    # thresholds, peaks, 3-D location
    count(tree, settings=None) -> DataTree     # counts, density, scores against the truth
    images_of(tree) -> Images                  # the images as arrays
    detections_of(tree) -> xarray.Dataset      # one row per detection
    counts_of(tree) -> xarray.Dataset          # one row per ping
    track(tree, settings=None) -> DataTree     # fish tracks across pings, scored against the truth
    tracks_of(tree) -> xarray.Dataset          # one row per track, and per track point
    open_tree(path), write_tree(tree, path)    # the dataset I/O (atomic writes)
    ProcessingSettings, load_settings(path)
"""
from __future__ import annotations

import importlib

#: public name -> module that defines it
_API = {
    "image": "processing.products", "detect": "processing.products", "count": "processing.products",
    "images_of": "processing.products", "detections_of": "processing.products",
    "counts_of": "processing.products", "count_summary": "processing.products",
    "format_counts": "processing.products", "volume_of": "processing.products",
    "write_csv": "processing.products", "resolve_settings": "processing.products",
    "open_tree": "processing.dataset", "write_tree": "processing.dataset",
    "read_record": "processing.dataset", "DatasetError": "processing.dataset",
    "Images": "processing.imaging",
    "NoiseEstimateError": "processing.noise",
    "ConfigError": "processing.config",
    "ProcessingSettings": "processing.settings", "ImageSettings": "processing.settings",
    "load_settings": "processing.settings",
    "track": "processing.tracks", "tracks_of": "processing.tracks",
}

__all__ = sorted(_API)


def __getattr__(name):
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'processing' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
