"""Sonar images from per-element echoes (thesis chapter 4), for simulated and recorded data alike.

:func:`form_images` turns a :class:`~processing.base.dataset.SonarRecord` into complex azimuth–range
images I(r, θ), one per image group (A and B in interferometric mode), and, in interferometric
mode, the interferometric phase ψ_AB and elevation φ of every cell. Image amplitudes are
calibrated: a point target's peak is its echo amplitude at one element (ADC counts). The noise
power gains of the filters are returned so that the expected noise level of an image follows
from the channel noise (:attr:`Images.noise_power_gain`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from processing.imaging.beamforming import (SubarrayGeometry, beamform_das, beamform_fft, beamform_wideband,
                          default_beam_angles, fft_beam_angles)
from processing.imaging.compression import RangeFilter, compressed_spectra, to_time
from processing.base.dataset import SonarRecord
from processing.imaging.interferometry import elevation_from_phase, interferogram
from processing.settings import ImageSettings

__all__ = ["Images", "form_images", "range_axis"]


@dataclass(frozen=True, eq=False)
class Images:
    """Images of every ping.

    The interferometric phase and the elevation are functions of the two images; they are
    derived on first use (:attr:`psi_rad`, :attr:`elevation_rad`) or at chosen cells
    (:meth:`psi_at`), never stored twice.

    Attributes
    ----------
    image : ndarray, shape (n_pings, n_groups, n_range, n_beams), complex
        I(r, θ) per image group, calibrated in ADC counts (echo amplitude at one element).
    groups : tuple of str
        Image group names ("A", "B"; "A" in normal mode; "AB" in combined mode).
    range_m : ndarray, shape (n_range,)
        c t / 2 of each image row (m).
    time_s : ndarray, shape (n_range,)
        Two-way delay of each row (s) since the start of transmission.
    beam_angle_rad : ndarray, shape (n_beams,)
    noise_power_gain : float
        Image noise power / channel noise power for white channel noise over the receiver band
        (per quadrature component).
    settings : ImageSettings
        The settings the images were formed with.
    phase_centers_m : dict of str -> ndarray, shape (3,)
        Phase centre (m, sonar frame) of each image group's subarray.
    range_resolution_m, azimuth_resolution_rad : float
        Measured 3 dB widths of a point target's image cell.
    wavelength_m : float
        λ at the carrier (m), for the elevation.
    interferometric : bool
        Whether the images are the A/B pair of interferometric mode.

    Image peaks are calibrated: a target on a beam and sample peaks at its echo amplitude at one
    element (signal gain 1).
    """

    image: np.ndarray
    groups: tuple
    range_m: np.ndarray
    time_s: np.ndarray
    beam_angle_rad: np.ndarray
    noise_power_gain: float
    settings: ImageSettings
    phase_centers_m: dict = field(default_factory=dict)
    range_resolution_m: float = 0.0
    azimuth_resolution_rad: float = 0.0
    wavelength_m: float = float("nan")
    interferometric: bool = False

    @property
    def interpolation(self) -> int:
        """Range interpolation factor of the images (samples per range cell of the data)."""
        return int(self.settings.interpolation)

    def group_index(self, group: str) -> int:
        """Index of an image group along axis 1 of :attr:`image`.

        Raises
        ------
        ValueError
            Not an image of these images (the message lists them).
        """
        if group not in self.groups:
            raise ValueError(f"image group {group!r} is not an image of this dataset "
                             f"(images: {', '.join(self.groups)})")
        return self.groups.index(group)

    @property
    def baseline_m(self) -> np.ndarray | None:
        """Phase centre of B minus that of A (m), shape (3,); None unless interferometric."""
        if not self.interferometric:
            return None
        return np.asarray(self.phase_centers_m["B"], float) - np.asarray(self.phase_centers_m["A"], float)

    def psi_at(self, ping, row, beam) -> np.ndarray:
        """ψ_AB = arg(I_A I_B*) (rad) at chosen cells, each index array of shape (n,)."""
        if not self.interferometric:
            raise ValueError("no interferometric phase: the images are not an A/B pair")
        ia, ib = self.groups.index("A"), self.groups.index("B")
        return np.angle(self.image[ping, ia, row, beam] * np.conj(self.image[ping, ib, row, beam]))

    @cached_property
    def psi_rad(self) -> np.ndarray | None:
        """ψ_AB of every cell (rad), shape (n_pings, n_range, n_beams); None unless
        interferometric."""
        if not self.interferometric:
            return None
        ia, ib = self.groups.index("A"), self.groups.index("B")
        return interferogram(self.image[:, ia], self.image[:, ib])[1]

    @cached_property
    def _elevation(self):
        if not self.interferometric:
            return None, None
        return elevation_from_phase(self.psi_rad, self.beam_angle_rad, self.baseline_m,
                                    self.wavelength_m)

    @property
    def elevation_rad(self) -> np.ndarray | None:
        """Elevation φ (rad) of every cell from ψ_AB, shape (n_pings, n_range, n_beams)."""
        return self._elevation[0]

    @property
    def elevation_clipped(self) -> np.ndarray | None:
        """Cells whose arcsin argument exceeded 1 (elevation clipped), bool, same shape."""
        return self._elevation[1]

    def pings(self, index) -> "Images":
        """The images of some pings (``index``: a slice or an index array)."""
        return replace(self, image=self.image[index])


def _width_3db(profile, step):
    p = profile / profile.max()
    i = int(np.argmax(p))
    above = p >= 0.5 ** 0.5
    lo, hi = i, i
    while lo > 0 and above[lo - 1]:
        lo -= 1
    while hi < p.size - 1 and above[hi + 1]:
        hi += 1
    return (hi - lo + 1) * step


_RESOLUTION: dict = {}


def resolution(rfilter: RangeFilter, geometry: SubarrayGeometry, sound_speed_m_s: float,
               wavelength_m: float):
    """3 dB widths of the point response: range (m, from the compressed pulse) and azimuth (rad,
    from the weighted array factor at broadside). Used as the resolution cell for scoring.
    Remembered per filter and geometry (a long record is imaged a chunk of pings at a time)."""
    key = (np.asarray(rfilter.response).tobytes(), rfilter.rate_hz, geometry.positions_m.tobytes(),
           geometry.weights.tobytes(), float(sound_speed_m_s), float(wavelength_m))
    if key not in _RESOLUTION:
        if len(_RESOLUTION) > 32:
            _RESOLUTION.clear()
        _RESOLUTION[key] = _resolution(rfilter, geometry, sound_speed_m_s, wavelength_m)
    return _RESOLUTION[key]


def _resolution(rfilter, geometry, sound_speed_m_s, wavelength_m):
    spec = rfilter.response
    n, up = rfilter.nfft, 32
    big = np.zeros(n * up)
    h = n // 2
    big[:h], big[n * up - (n - h):] = spec[:h], spec[h:]
    pulse = np.fft.fftshift(np.abs(np.fft.ifft(big)))
    dt = 1.0 / (rfilter.rate_hz * up)
    dr = _width_3db(pulse, dt) * sound_speed_m_s / 2
    u = np.linspace(-0.5, 0.5, 20001)
    x = geometry.positions_m[:, 0] - geometry.center_m[0]
    af = np.abs(np.exp(2j * np.pi / wavelength_m * np.outer(u, x)) @ geometry.weights)
    dtheta = _width_3db(af, u[1] - u[0])
    return float(dr), float(dtheta)


def range_axis(record: SonarRecord, upsample: int):
    """Time (s) and range c t/2 (m) of every interpolated output sample, shape (N·U,)."""
    n = record.samples.shape[-1] * upsample
    t = record.time_offset_s + np.arange(n) / (record.rate_hz * upsample)
    return t, record.sound_speed_m_s * t / 2


def form_images(record: SonarRecord, settings: ImageSettings | None = None, *,
                noise_band_hz: float | None = None) -> Images:
    """Pulse compression, interpolation, beamforming and interferometry for every ping.

    Parameters
    ----------
    record : SonarRecord
    settings : ImageSettings, optional
        Defaults: the thesis' (Hamming windows, 4x interpolation, 13–26 m, FFT beams).
    noise_band_hz : float, optional
        The receiver noise band, for the expected noise gain; default the whole sampled band.

    Returns
    -------
    Images
    """
    st = settings or ImageSettings()
    up = st.interpolation
    lam = record.wavelength_m
    n_ping, _, n = record.samples.shape
    rf = RangeFilter.design(record.replica, n_samples=n, rate_hz=record.rate_hz,
                            bandwidth_hz=record.bandwidth_hz, range_window=st.range_window)
    t, r = range_axis(record, up)
    if st.range_m is not None:
        rows = np.flatnonzero((r >= st.range_m[0]) & (r <= st.range_m[1]))
        if rows.size == 0:
            raise ValueError(f"{record.source}: image range {st.range_m[0]:g}–{st.range_m[1]:g} m "
                             f"lies outside the record ({r[0]:.2f}–{r[-1]:.2f} m)")
    else:
        rows = np.arange(r.size)
    keep = slice(int(rows[0]), int(rows[-1]) + 1)
    groups = record.image_groups
    geoms = {g: SubarrayGeometry(record.element_position_m[idx], st.spatial_window)
             for g, idx in groups.items()}
    first = next(iter(geoms.values()))
    # one beam grid for every image, so that interferometry compares like with like
    if st.beamformer == "fft":
        n_beams = st.n_beams or int(2 ** np.ceil(np.log2(max(2 * first.n_elements, 2))))
        angles = fft_beam_angles(n_beams, first.pitch_m, lam)
        sel = (np.ones(angles.size, bool) if st.azimuth_span is None
               else np.abs(angles) <= st.azimuth_span / 2 + 1e-12)
    else:
        angles = default_beam_angles(first, lam, n_beams=st.n_beams, span_rad=st.azimuth_span)
        sel = np.ones(angles.size, bool)
    beams = np.flatnonzero(sel)
    out = np.empty((n_ping, len(groups), rows.size, beams.size), np.complex128)
    for p in range(n_ping):
        spec = compressed_spectra(record.samples[p], rf)
        for gi, (g, idx) in enumerate(groups.items()):
            geo = geoms[g]
            if st.beamformer == "wideband":
                bspec = beamform_wideband(spec[idx], geo, angles, wavelength_m=lam,
                                          sound_speed_m_s=record.sound_speed_m_s,
                                          center_frequency_hz=record.center_frequency_hz,
                                          rate_hz=record.rate_hz)
                img = np.swapaxes(to_time(bspec, rf, upsample=up, keep=keep), 0, 1)
                out[p, gi] = img[:, sel]
            else:
                y = to_time(spec[idx], rf, upsample=up, keep=keep)
                if st.beamformer == "fft":
                    beamform_fft(y, geo, n_beams, lam, beams=beams, out=out[p, gi])
                else:
                    out[p, gi] = beamform_das(y, geo, angles, lam)[:, sel]
    angles = angles[sel]
    names = tuple(groups)
    gain = rf.noise_power_gain(noise_band_hz) * first.noise_power_gain()
    dr, dth = resolution(rf, first, record.sound_speed_m_s, lam)
    return Images(out, names, r[rows], t[rows], angles, gain, st,
                  phase_centers_m={g: geoms[g].center_m for g in names}, range_resolution_m=dr,
                  azimuth_resolution_rad=dth, wavelength_m=lam,
                  interferometric=record.mode == "interferometric" and {"A", "B"} <= set(names))
