"""Processing settings: the ``processing`` section of a scene file, or a YAML of their own.

Every field has the thesis' value as its default (Tables 6.2, 6.3, 6.5); see
docs/conventions.md for units.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from .config import (AngleDeg, ConfigModel, PositiveCount, PositiveReal, read_yaml,
                     validate_file)

__all__ = ["ImageSettings", "ProcessingSettings", "load_settings", "WINDOWS"]

#: windows accepted by name (scipy.signal.windows), range and spatial
WINDOWS = ("rectangular", "hamming", "hann", "taylor", "blackman")


class ImageSettings(ConfigModel):
    """Pulse compression, interpolation and beamforming (thesis chapter 4)."""

    range_m: tuple[PositiveReal, PositiveReal] | None = (13.0, 26.0)
    """Image range limits (m); null keeps the whole record."""
    range_window: Literal[WINDOWS] = "hamming"
    """Range (frequency-domain) weighting of the matched filter (§4.3)."""
    interpolation: PositiveCount = Field(4, le=64)
    """Band-limited interpolation factor in range; 1 = off (§4.4)."""
    beamformer: Literal["fft", "delay_and_sum", "wideband"] = "fft"
    """fft: zero-padded FFT with phase-centre correction; delay_and_sum: exact narrowband
    phases; wideband: true time delays (the reference)."""
    n_beams: PositiveCount | None = 32
    """Number of beams; null meets the spatial Nyquist rate over the span."""
    azimuth_span: AngleDeg(0, 180, lo_open=True) | None = Field(None, alias="azimuth_span_deg")
    """Full scan span (deg); null = the grating-lobe-free span arcsin(λ/d)."""
    spatial_window: Literal[WINDOWS] = "hamming"
    """Across-array weighting (§4.5.5)."""

    @model_validator(mode="after")
    def _range_order(self):
        if self.range_m is not None and not self.range_m[0] < self.range_m[1]:
            raise ValueError("range_m must be [near, far] with near < far")
        return self


class ProcessingSettings(ConfigModel):
    """All processing settings."""

    image: ImageSettings = ImageSettings()


def load_settings(path: str | Path) -> ProcessingSettings:
    """Read processing settings from their own YAML file (same keys as a scene's
    ``processing`` section). Raises :class:`processing.config.ConfigError`."""
    data, marks = read_yaml(path)
    return validate_file(ProcessingSettings, data, file=path, marks=marks)
