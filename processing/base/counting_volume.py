"""The counting volume, counts and density (thesis §5.3.1, §6.2; Table 6.3).

The counting volume is a sector of the sonar frame: ranges r1 <= r <= r2 from the origin (the
transmitter's phase centre), |θ| <= θ_h and |φ| <= φ_h, with θ = atan2(x, z) and
φ = atan2(y, √(x² + z²)) as in docs/conventions.md. By default θ_h and φ_h are half the
transmitter's 3 dB beamwidths read from the dataset (``/Sonar/beamwidth_transmit_major/minor``)
and [r1, r2] the image's range limits. Its volume is exact:

    V = (r2³ − r1³)/3 · 2θ_h · 2 sin φ_h          (13.8 m³ for ABACUS at 13–26 m)

Counts per ping: *before interferometry* every detection whose range and azimuth fall in the
volume's span (elevation unknown); *after* only those whose 3-D position lies inside.

Two densities, because a counting volume is a fixed sector and a school is not:

``density_per_m3``           count / V: the density *of the counting volume*. Where the fish
                             occupy only part of its range (a school at 15–25 m in a 13–26 m
                             volume) it reads low by the empty fraction (20 % there).
``occupied_density_per_m3``  count / V_occ, V_occ the part of the volume between the nearest and
                             farthest ranges the run's located targets occupy: the density *where
                             the targets are*. The range extent of n points uniform in a layer
                             underestimates the layer by 2/(n + 1) of its width (order statistics),
                             so the observed extent is widened by that factor; with the hundreds of
                             detections of a run the estimate is within a few per cent.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CountingVolume", "counting_volume", "occupied_range", "DEFAULT_IMAGE_RANGE_M",
           "image_range_of"]

#: the image's range limits by default (m): the thesis' 13–26 m (processing.settings.ImageSettings)
DEFAULT_IMAGE_RANGE_M = (13.0, 26.0)


def image_range_of(processing_block, window_m) -> tuple:
    """The image's range limits a run file's ``processing:`` block asks for, as the counting
    volume of the simulator's ground truth uses them (the one piece of the processing settings
    the forward model needs, read here so that it needs no more of them).

    Parameters
    ----------
    processing_block : mapping or None
        The ``processing:`` section as written (``image.range_m`` is read; the rest is
        validated by :class:`processing.settings.ProcessingSettings` where it is used).
    window_m : (float, float)
        The recorded range window (m): the limits when ``image.range_m`` is null.

    Returns
    -------
    (float, float)
        Near and far range (m).

    Raises
    ------
    ValueError
        ``image.range_m`` is not two increasing positive numbers (the message names the key).
    """
    image = (processing_block or {}).get("image") if isinstance(processing_block, dict) else None
    if not isinstance(image, dict) or "range_m" not in image:
        return DEFAULT_IMAGE_RANGE_M
    value = image["range_m"]
    if value is None:
        return (float(window_m[0]), float(window_m[1]))
    try:
        near, far = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"processing.image.range_m: {value!r} is not [near, far] in m") from None
    if not (0 < near < far and np.isfinite(far)):
        raise ValueError(f"processing.image.range_m: [{near}, {far}] must be [near, far] with "
                         f"0 < near < far (m)")
    return (near, far)


@dataclass(frozen=True)
class CountingVolume:
    """A sonar-frame sector.

    Attributes
    ----------
    range_m : (float, float)
    azimuth_halfwidth_rad, elevation_halfwidth_rad : float
    """

    range_m: tuple
    azimuth_halfwidth_rad: float
    elevation_halfwidth_rad: float

    @property
    def volume_m3(self) -> float:
        r1, r2 = self.range_m
        return float((r2**3 - r1**3) / 3 * 2 * self.azimuth_halfwidth_rad
                     * 2 * np.sin(self.elevation_halfwidth_rad))

    def sector_volume_m3(self, range_m) -> float:
        """Volume (m³) of the sector between two ranges (clipped to the volume's own)."""
        r1 = max(float(range_m[0]), self.range_m[0])
        r2 = min(float(range_m[1]), self.range_m[1])
        if r2 <= r1:
            return 0.0
        return float((r2**3 - r1**3) / 3 * 2 * self.azimuth_halfwidth_rad
                     * 2 * np.sin(self.elevation_halfwidth_rad))

    def in_span(self, range_m, azimuth_rad):
        """Range and azimuth inside (elevation ignored), shape of the inputs."""
        r = np.asarray(range_m, float)
        return ((r >= self.range_m[0]) & (r <= self.range_m[1])
                & (np.abs(np.asarray(azimuth_rad, float)) <= self.azimuth_halfwidth_rad))

    def contains(self, positions_m):
        """Sonar-frame positions (n, 3) inside the sector, shape (n,)."""
        p = np.asarray(positions_m, float).reshape(-1, 3)
        r = np.linalg.norm(p, axis=1)
        az = np.arctan2(p[:, 0], p[:, 2])
        el = np.arctan2(p[:, 1], np.hypot(p[:, 0], p[:, 2]))
        return self.in_span(r, az) & (np.abs(el) <= self.elevation_halfwidth_rad)


def counting_volume(*, tx_beamwidth_az_rad: float, tx_beamwidth_el_rad: float, image_range_m,
                    settings=None) -> CountingVolume:
    """The counting volume from the transmitter's beamwidths and the image range, with any
    overrides of ``settings`` (a :class:`~processing.settings.CountSettings`)."""
    az = tx_beamwidth_az_rad / 2
    el = tx_beamwidth_el_rad / 2
    rng = tuple(float(r) for r in image_range_m)
    if settings is not None:
        az = settings.azimuth_halfwidth if settings.azimuth_halfwidth is not None else az
        el = settings.elevation_halfwidth if settings.elevation_halfwidth is not None else el
        rng = tuple(settings.range_m) if settings.range_m is not None else rng
    if not (np.isfinite(az) and az > 0 and np.isfinite(el) and el > 0):
        raise ValueError("the counting volume needs positive azimuth and elevation half-widths")
    return CountingVolume(rng, float(az), float(el))


def occupied_range(range_m, volume: CountingVolume):
    """The range layer the located targets of a run occupy, or None (fewer than 2 targets).

    Parameters
    ----------
    range_m : array_like, shape (n,)
        Ranges (m) of the detections located inside the counting volume, every ping together.
    volume : CountingVolume

    Returns
    -------
    (float, float) or None
        [r_min − e, r_max + e] clipped to the volume, e = (r_max − r_min) / (n − 1): the
        unbiased extent of a uniform layer from its n samples' range (n + 1)/(n − 1).
    """
    r = np.sort(np.asarray(range_m, float))
    if r.size < 2:
        return None
    pad = (r[-1] - r[0]) / (r.size - 1)
    return (max(volume.range_m[0], float(r[0] - pad)), min(volume.range_m[1], float(r[-1] + pad)))
