"""abacus.processing — the inverse problem: echoes -> images -> detections -> counts.

Works from the data contract alone (processing.dataset), so it runs the same on simulated and
recorded data; it never imports acoustics. Public surface::

    image(tree, settings=None) -> DataTree       # pulse compression, beamforming, interferometry
    open_tree(path), write_tree(tree, path)      # the dataset I/O (atomic writes)
    ProcessingSettings, load_settings(path)
"""
from .config import ConfigError
from .dataset import DatasetError, open_tree, read_record, write_tree
from .products import (count, count_summary, counts_of, format_counts, detect, detections_of, image, images_of,
                       resolve_settings, volume_of, write_csv)
from .noise import NoiseEstimateError
from .settings import ImageSettings, ProcessingSettings, load_settings

__all__ = ["image", "detect", "count", "count_summary", "format_counts", "images_of", "detections_of", "counts_of", "volume_of",
           "write_csv", "NoiseEstimateError", "resolve_settings", "open_tree", "write_tree", "read_record",
           "DatasetError", "ConfigError", "ProcessingSettings", "ImageSettings", "load_settings"]
