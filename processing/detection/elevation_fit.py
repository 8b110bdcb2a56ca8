"""A detection's interferometric phase from a fit of two point responses (``detect.elevation: fit``).

Two fish within about a resolution cell of each other give one merged echo, and the phase of
I_A I_B* at its peak is the phase of the sum of their echoes: their elevations mixed, and where
the echoes partly cancel, outside the span of the two ("glint", the angle error of monopulse and
split-aperture systems on unresolved targets). It is coherent over the echo, so neither more SNR
nor averaging the phase over the echo's samples removes it (docs/validation.md, "Counting
against density": averaging over half a range cell changes the false counts' elevations by
< 0.05°). What does is a model with two targets:

    I_g(t_i, u_k) = Σ_j a_jg p(t_i − τ_j) AF(u_k − u_j),     g ∈ {A, B},  j = 1, 2,

p the compressed pulse (the range filter's response) and AF the weighted subarray's array factor,
fitted to both images over ±1.5 range cells × ±2 beams around the peak: the amplitudes a_jg by
linear least squares for given (τ_j, u_j) (variable projection), the delays and direction sines
by Levenberg–Marquardt from four starts half a cell apart. Where the one-target fit leaves more
than :data:`TRIGGER_DB` of the patch's energy (an isolated fish leaves −40 to −47 dB: the model's
own error) and two targets lower the residual by at least :data:`GAIN_DB`, the component nearest
the peak is the detection where it lies inside the patch (outside, the fit extrapolates): its
ψ_AB = arg(a_A a_B*), its delay and direction (ψ_AB depends on the azimuth through the
baseline's x part, so the elevation is taken at the component's own azimuth). Elsewhere the
peak's ψ stands (the reference, ``detect.elevation: peak``). Detections below
:data:`MIN_SNR_DB` keep the peak's ψ: there noise, not a neighbour, sets the phase error.
"""
from __future__ import annotations

import numpy as np

from processing.detection.locate import locate, to_world
from processing.imaging.beamforming import SubarrayGeometry
from processing.imaging.compression import RangeFilter
from processing.imaging.interferometry import elevation_from_phase

__all__ = ["PointResponse", "point_response", "fit_detections", "relocate", "TRIGGER_DB", "GAIN_DB",
           "MIN_SNR_DB"]

#: the one-target fit's residual (dB of the patch's energy) above which two targets are tried
TRIGGER_DB = -30.0
#: how much (dB) two targets must lower the residual to be taken
GAIN_DB = 6.0
#: detections weaker than this (dB above the noise) keep the peak's phase
MIN_SNR_DB = 30.0
#: range samples of the pulse table per native sample, and its half-length in native samples
_FINE = 64
_HALF = 200


class PointResponse:
    """The image of a point target: compressed pulse p(t) × array factor AF(Δu).

    Parameters
    ----------
    record : SonarRecord
        For the replica, sampling rate, band, element positions and wavelength.
    image_settings : ImageSettings
        Range and spatial windows.
    """

    def __init__(self, record, image_settings):
        rf = RangeFilter.design(record.replica, n_samples=record.samples.shape[-1], rate_hz=record.rate_hz,
                                bandwidth_hz=record.bandwidth_hz, range_window=image_settings.range_window)
        n = rf.nfft
        big = np.zeros(n * _FINE, complex)
        h = (n + 1) // 2
        big[:h], big[n * _FINE - (n - h):] = rf.response[:h], rf.response[h:]
        p = np.fft.ifft(big) * _FINE
        half = _HALF * _FINE
        self.grid_s = np.arange(-half, half + 1) / (record.rate_hz * _FINE)
        self.pulse = np.concatenate([p[-half:], p[:half + 1]])
        group = "A" if "A" in record.image_groups else next(iter(record.image_groups))
        geo = SubarrayGeometry(record.element_position_m[record.image_groups[group]],
                               image_settings.spatial_window)
        self.x_m = geo.positions_m[:, 0] - geo.center_m[0]
        self.weights = geo.weights / geo.weights.sum()
        self.k = 2 * np.pi / record.wavelength_m

    def columns(self, t_s, u, tau_s, u_t):
        """Images of unit targets, shape (n_t · n_u, n_targets).

        Parameters
        ----------
        t_s : ndarray, shape (n_t,)
            Delays of the image rows (s).
        u : ndarray, shape (n_u,)
            Sines of the beam angles.
        tau_s, u_t : ndarray, shape (n_targets,)
            The targets' delays (s) and direction sines.
        """
        cols = []
        for a, b in zip(tau_s, u_t):
            pr = (np.interp(t_s - a, self.grid_s, self.pulse.real, 0.0, 0.0)
                  + 1j * np.interp(t_s - a, self.grid_s, self.pulse.imag, 0.0, 0.0))
            af = np.exp(1j * self.k * np.multiply.outer(u - b, self.x_m)) @ self.weights
            cols.append(np.outer(pr, af).ravel())
        return np.stack(cols, -1)

    def fit(self, patch_a, patch_b, t_s, u, x0):
        """Least-squares targets for two image patches.

        Parameters
        ----------
        patch_a, patch_b : ndarray, shape (n_t, n_u), complex
        t_s, u : ndarray, shapes (n_t,), (n_u,)
        x0 : ndarray, shape (2 n,)
            Starting delays (s) then sines of n targets.

        Returns
        -------
        x : ndarray, shape (2 n,)
        amplitudes : ndarray, shape (n, 2), complex
            a_A, a_B of each target.
        residual : float
            Residual energy / patch energy (0 for a perfect fit; 1 where the patch is empty).
        """
        from scipy.optimize import least_squares
        y = np.stack([patch_a.ravel(), patch_b.ravel()], -1)
        energy = float(np.sum(np.abs(y) ** 2))
        n = len(x0) // 2
        if energy == 0:
            return np.asarray(x0, float), np.zeros((n, 2), complex), 1.0

        def solve(x):
            m = self.columns(t_s, u, x[:n], x[n:])
            return m, np.linalg.lstsq(m, y, rcond=None)[0]

        def res(x):
            m, c = solve(x)
            r = y - m @ c
            return np.concatenate([r.real.ravel(), r.imag.ravel()])
        x = least_squares(res, x0, x_scale=np.r_[[1e-5] * n, [0.01] * n], method="lm").x
        m, c = solve(x)
        return x, c, float(np.sum(np.abs(y - m @ c) ** 2) / energy)


_RESPONSES: dict = {}


def point_response(record, image_settings) -> PointResponse:
    """The record's :class:`PointResponse`, remembered per replica, rate, band and geometry."""
    key = (np.asarray(record.replica).tobytes(), float(record.rate_hz), float(record.bandwidth_hz),
           int(record.samples.shape[-1]), np.asarray(record.element_position_m).tobytes(),
           float(record.wavelength_m), image_settings.range_window, image_settings.spatial_window)
    # the chain's threads share the cache: each returns the response it read or made, never a
    # second lookup that another thread's clear() may have emptied in between
    response = _RESPONSES.get(key)
    if response is None:
        response = PointResponse(record, image_settings)
        if len(_RESPONSES) > 8:
            _RESPONSES.clear()
        _RESPONSES[key] = response
    return response


def fit_detections(images, record, ping, row, beam, range_m, azimuth_rad, snr_db):
    """ψ_AB, azimuth and range of detections from the two-target fit where it is taken.

    Parameters
    ----------
    images : Images
        Interferometric images holding the detections' pings.
    record : SonarRecord
    ping, row, beam : ndarray of int, shape (n,)
        Each detection's ping (index into ``images.image``), peak row and beam.
    range_m, azimuth_rad : ndarray, shape (n,)
        The refined peak positions (m, rad).
    snr_db : ndarray, shape (n,)
        NaN counts as below :data:`MIN_SNR_DB`.

    Returns
    -------
    psi_rad, azimuth_rad, range_m : ndarray, shape (n,)
        NaN where the peak's values stand.
    taken : ndarray of bool, shape (n,)
        Where the two-target fit was taken.
    """
    n = len(ping)
    psi, az, rg = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    taken = np.zeros(n, bool)
    if n == 0 or not images.interferometric:
        return psi, az, rg, taken
    resp = point_response(record, images.settings)
    ia, ib = images.group_index("A"), images.group_index("B")
    c = record.sound_speed_m_s
    dr, du = images.range_resolution_m, images.azimuth_resolution_rad
    step = float(np.diff(images.range_m[:2])[0]) if images.range_m.size > 1 else dr
    half_rows = max(1, int(round(1.5 * dr / step)))
    t_ax, u_ax = images.time_s, np.sin(images.beam_angle_rad)
    with np.errstate(invalid="ignore"):
        strong = np.asarray(snr_db, float) >= MIN_SNR_DB
    for i in np.flatnonzero(strong):
        p, r, b = int(ping[i]), int(row[i]), int(beam[i])
        r0, r1 = max(r - half_rows, 0), min(r + half_rows + 1, t_ax.size)
        b0, b1 = max(b - 2, 0), min(b + 3, u_ax.size)
        pa, pb = images.image[p, ia, r0:r1, b0:b1], images.image[p, ib, r0:r1, b0:b1]
        tt, uu = t_ax[r0:r1], u_ax[b0:b1]
        tau0, u0 = 2 * range_m[i] / c, np.sin(azimuth_rad[i])
        x1, _, e1 = resp.fit(pa, pb, tt, uu, np.array([tau0, u0]))
        if not e1 > 10 ** (TRIGGER_DB / 10):
            continue
        best = (None, None, np.inf)
        dt, ds = dr / c, du / 2          # half a cell in delay (2 dr / c / 2) and in sine
        for oa, ob in ((dt, 0.0), (0.0, ds), (dt, ds), (dt, -ds)):
            x0 = np.array([x1[0] - oa / 2, x1[0] + oa / 2, x1[1] - ob / 2, x1[1] + ob / 2])
            fit = resp.fit(pa, pb, tt, uu, x0)
            if fit[2] < best[2]:
                best = fit
        if not best[2] <= e1 * 10 ** (-GAIN_DB / 10):
            continue
        x2, a2 = best[0], best[1]
        r2 = x2[:2] * c / 2
        j = int(np.argmin(np.hypot((r2 - range_m[i]) / dr, (x2[2:] - u0) / du)))
        if not (np.all(np.isfinite(x2)) and abs(x2[2 + j]) <= 1):
            continue
        # a component outside the fitted patch is an extrapolation the patch's samples do not
        # constrain (a sidelobe or ghost cell's fit reaching for the echo it belongs to, or past
        # the image's edge): the detection is not that component, and its peak stands
        if not (tt[0] <= x2[j] <= tt[-1] and uu.min() <= x2[2 + j] <= uu.max()):
            continue
        psi[i] = np.angle(a2[j, 0] * np.conj(a2[j, 1]))
        az[i], rg[i] = np.arcsin(x2[2 + j]), r2[j]
        taken[i] = True
    return psi, az, rg, taken


def relocate(table: dict, index, psi_rad, azimuth_rad, range_m, *, record, images, volume, pose=None):
    """Write new ψ, azimuth and range of some detections into the table and locate them again.

    Parameters
    ----------
    table : dict of ndarray
        The detections table (:class:`processing.detection.detect.Detections`); changed in place.
    index : ndarray of int, shape (m,)
        Rows to change.
    psi_rad, azimuth_rad, range_m : ndarray, shape (m,)
    record : SonarRecord
    images : Images
        For the phase centres and baseline.
    volume : CountingVolume
    pose : (position_m, rotation), optional
        As :func:`processing.detection.detect.detect_all` takes it, indexed by ``table["ping"]``.
    """
    index = np.asarray(index, int)
    if index.size == 0:
        return
    centers = images.phase_centers_m
    pos = locate(2 * np.asarray(range_m) / record.sound_speed_m_s, azimuth_rad, psi_rad,
                 transmitter_m=record.transmitter_center_m, center_a_m=centers["A"], center_b_m=centers["B"],
                 sound_speed_m_s=record.sound_speed_m_s, wavelength_m=record.wavelength_m)
    el, clipped = elevation_from_phase(psi_rad, azimuth_rad, images.baseline_m, record.wavelength_m)
    position, rotation = pose if pose is not None else (np.zeros(3), np.eye(3))
    position, rotation = np.asarray(position, float), np.asarray(rotation, float)
    if rotation.ndim == 3:
        p = table["ping"][index]
        world = np.einsum("nij,nj->ni", rotation[p], pos) + position[p]
    else:
        world = to_world(pos, position, rotation)
    table["psi_rad"][index] = psi_rad
    table["azimuth_rad"][index] = azimuth_rad
    table["range_m"][index] = range_m
    table["elevation_rad"][index] = el
    table["elevation_clipped"][index] = clipped
    for k, a in enumerate("xyz"):
        table[f"{a}_m"][index] = pos[:, k]
        table[f"world_{a}_m"][index] = world[:, k]
    table["in_span"][index] = volume.in_span(range_m, azimuth_rad)
    table["in_volume"][index] = volume.contains(pos)
