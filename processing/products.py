"""Processing products in the dataset (the /Processing group) and the public entry points.

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
import yaml

from .config import ConfigError, dump_yaml, validate_file
from .dataset import ELEMENT_GROUP, DatasetError, read_record, split_complex
from .imaging import Images, form_images
from .settings import ImageSettings, ProcessingSettings, load_settings

__all__ = ["PROCESSING_GROUP", "resolve_settings", "image", "images_of"]

PROCESSING_GROUP = "Processing"


def resolve_settings(tree: xr.DataTree | None, settings=None) -> ProcessingSettings:
    """The processing settings to use (see module docstring)."""
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
    if tree is not None and "Provenance" in tree.children:
        text = tree["Provenance"].ds.attrs.get("scene_text", "")
        if text:
            section = (yaml.safe_load(text) or {}).get("processing")
            if section is not None:
                try:
                    return validate_file(ProcessingSettings, section,
                                         file="/Provenance scene_text (processing section)")
                except ConfigError:
                    raise
    return ProcessingSettings()


def _noise_band(tree) -> float | None:
    attrs = tree[ELEMENT_GROUP].ds.attrs
    for key in ("noise_bandwidth_hz", "receiver_bandwidth_hz"):
        if key in attrs:
            return float(attrs[key])
    return None


def images_dataset(im: Images, ping_time, settings: ProcessingSettings) -> xr.Dataset:
    """/Processing variables of an :class:`Images`."""
    dims = ("ping_time", "image_group", "image_range", "beam")
    ds = xr.Dataset(
        {**split_complex("image", im.image, dims, {"units": "ADC counts",
                                                   "long_name": "calibrated complex image I(r, θ): echo amplitude at one element"})},
        coords={"ping_time": ping_time, "image_group": list(im.groups),
                "image_range": ("image_range", im.range_m, {"units": "m", "long_name": "c t / 2"}),
                "image_time": ("image_range", im.time_s, {"units": "s", "long_name": "two-way delay"}),
                "beam": np.arange(im.beam_angle_rad.size),
                "beam_angle": ("beam", im.beam_angle_rad, {"units": "rad", "long_name": "azimuth θ of the beam axis"})},
        attrs={"settings_yaml": dump_yaml(settings.model_dump(mode="json", by_alias=True)),
               "image_noise_power_gain": im.noise_power_gain, "image_signal_gain": 1.0,
               "phase_centers_json": json.dumps({g: list(map(float, c)) for g, c in im.phase_centers_m.items()})})
    if im.psi_rad is not None:
        d3 = ("ping_time", "image_range", "beam")
        ds["interferometric_phase"] = xr.DataArray(im.psi_rad.astype(np.float32), dims=d3,
                                                   attrs={"units": "rad", "long_name": "ψ_AB = arg(I_A I_B*)"})
        ds["elevation"] = xr.DataArray(im.elevation_rad.astype(np.float32), dims=d3,
                                       attrs={"units": "rad", "long_name": "elevation φ from ψ_AB"})
        ds["elevation_clipped"] = xr.DataArray(im.elevation_clipped.astype(np.int8), dims=d3,
                                               attrs={"long_name": "1 where |arcsin argument| > 1 (clipped)"})
        ds["baseline"] = xr.DataArray(im.baseline_m, dims="xyz", attrs={"units": "m", "long_name": "phase centre of B minus A"})
    return ds


def image(tree: xr.DataTree, settings=None) -> xr.DataTree:
    """Images, interferometric phase and elevation of every ping (thesis chapter 4).

    Parameters
    ----------
    tree : xarray.DataTree
        A dataset following the data contract (simulated or recorded).
    settings : ProcessingSettings, ImageSettings, dict or path, optional

    Returns
    -------
    xarray.DataTree
        A copy of ``tree`` with /Processing added (replaced if present).

    Raises
    ------
    processing.dataset.DatasetError
        The dataset lacks what imaging needs (named in the message).
    """
    st = resolve_settings(tree, settings)
    rec = read_record(tree, source=str(tree.attrs.get("title", "dataset")))
    try:
        im = form_images(rec, st.image, noise_band_hz=_noise_band(tree))
    except ValueError as exc:
        raise DatasetError(str(exc)) from None
    out = tree.copy()
    ping_time = tree[ELEMENT_GROUP].ds["ping_time"].values
    out[PROCESSING_GROUP] = xr.DataTree(images_dataset(im, ping_time, st))
    return out


def images_of(tree: xr.DataTree) -> dict:
    """Arrays of /Processing as numpy (complex image rebuilt), for detection and plots."""
    if PROCESSING_GROUP not in tree.children:
        raise DatasetError("the dataset has no /Processing group: run processing.image first")
    ds = tree[PROCESSING_GROUP].ds
    out = {"image": ds["image_r"].values.astype(float) + 1j * ds["image_i"].values.astype(float),
           "groups": [str(g) for g in ds["image_group"].values],
           "range_m": ds["image_range"].values, "time_s": ds["image_time"].values,
           "beam_angle_rad": ds["beam_angle"].values,
           "noise_power_gain": float(ds.attrs.get("image_noise_power_gain", 1.0))}
    for k in ("interferometric_phase", "elevation", "elevation_clipped", "baseline"):
        out[k] = ds[k].values if k in ds else None
    return out
