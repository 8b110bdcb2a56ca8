"""Target strength of a detection, uncompensated and compensated for the two-way beam pattern.

A point target of backscatter amplitude ρ (σ_bs = ρ², TS = 20 log10 ρ) at range r, azimuth θ and
elevation φ peaks in the calibrated image at (processing/backscatter/calibration.py)

    |I| = G ρ |E_t(θ, φ)| |D(θ, φ)| 10^(−α r / 10) / r²,

so, as echosounders and Echoview define them,

    TS_uncomp = 20 log10(|I| r² 10^(α r / 10) / G)                 (the target taken on axis)
    TS_comp   = TS_uncomp − 20 log10(|E_t(θ, φ)| |D(θ, φ)|)         (at its located angles)

The two-way pattern is computed here from the element geometry the dataset carries (the
transmitter's elements in /Sonar, the receive elements of the imaged subarray in the element
group): each element a baffled rectangular piston, sinc·sinc of the direction cosines in its own
axes, and the transmitter the weighted sum of its elements with their far-field phases, normalised
to 1 on its axis — the far-field model of docs/arrays.md, independent of the simulator's code.
Compensation divides by the pattern; where the two-way pattern is below ``floor_db`` (a null, or
an elevation aliased outside the main lobe) TS_comp is NaN and says so, rather than inflating
the echo by tens of dB.
"""
from __future__ import annotations

import numpy as np

from processing.base.contract import ELEMENT_GROUP, ENVIRONMENT_GROUP, SONAR_GROUP
from processing.base.dataset import DatasetError, group_of

__all__ = ["BeamPattern", "beam_pattern_of", "target_strength_db"]


class BeamPattern:
    """The two-way far-field pattern |E_t| |D| of a dataset's sonar (cached element geometry).

    Parameters
    ----------
    tx_center_m : ndarray, shape (n_t, 3)
        Transmit element centres (m), sonar frame.
    tx_size_m : ndarray, shape (n_t, 2)
        Width (local x) and height (local y) of each transmit element (m).
    tx_rotation_rad, tx_weight : ndarray, shape (n_t,)
    rx_size_m : ndarray, shape (n_r, 2)
        Width and height of the receive elements of the imaged subarray (m).
    rx_rotation_rad : ndarray, shape (n_r,)
    wavenumber_rad_m : float
        k = 2π f_c / c.
    """

    def __init__(self, tx_center_m, tx_size_m, tx_rotation_rad, tx_weight, rx_size_m,
                 rx_rotation_rad, wavenumber_rad_m):
        self.tx_center_m = np.asarray(tx_center_m, float).reshape(-1, 3)
        self.tx_size_m = np.asarray(tx_size_m, float).reshape(-1, 2)
        self.tx_rotation_rad = np.asarray(tx_rotation_rad, float).ravel()
        self.tx_weight = np.asarray(tx_weight, float).ravel()
        self.rx_size_m = np.asarray(rx_size_m, float).reshape(-1, 2)
        self.rx_rotation_rad = np.asarray(rx_rotation_rad, float).ravel()
        self.k = float(wavenumber_rad_m)
        self._tx_ref = (self.tx_center_m * np.abs(self.tx_weight)[:, None]).sum(0) / np.abs(self.tx_weight).sum()

    def _pistons(self, u, size, rotation):
        """sinc·sinc of each direction (n, 3) for each element (m,): shape (n, m); np.sinc is 1 at
        0 (broadside exact), and nothing radiates behind the element plane."""
        c, s = np.cos(rotation), np.sin(rotation)
        ux = u[:, :1] * c + u[:, 1:2] * s
        uy = -u[:, :1] * s + u[:, 1:2] * c
        d = (np.sinc(0.5 * self.k * size[:, 0] * ux / np.pi)
             * np.sinc(0.5 * self.k * size[:, 1] * uy / np.pi))
        return np.where(u[:, 2:3] < 0.0, 0.0, d)

    def two_way(self, directions):
        """|E_t(u)| |D(u)| for unit directions ``u``.

        Parameters
        ----------
        directions : array_like, shape (n, 3)
            Sonar-frame directions (normalised here; a zero vector is taken as on-axis).

        Returns
        -------
        ndarray, shape (n,)
            The two-way amplitude pattern, 1 on the transmitter's axis for on-axis elements.
        """
        return self.transmit(directions) * self.receive(directions)

    @staticmethod
    def _unit(directions):
        u = np.asarray(directions, float).reshape(-1, 3)
        norm = np.linalg.norm(u, axis=1, keepdims=True)
        return np.where(norm > 0, u / np.where(norm > 0, norm, 1.0), np.array([0.0, 0.0, 1.0]))

    def transmit(self, directions):
        """|E_t(u)|: the transmitter's one-way pattern towards ``directions`` (n, 3), shape (n,)
        (1 on its axis)."""
        u = self._unit(directions)
        phase = np.exp(1j * self.k * ((self.tx_center_m - self._tx_ref) @ u.T)).T    # (n, n_t)
        return np.abs((self._pistons(u, self.tx_size_m, self.tx_rotation_rad) * phase)
                      @ self.tx_weight) / np.abs(self.tx_weight.sum())

    def transmit_at(self, points_m):
        """|E_t(P)| at points ``points_m`` (n, 3) (m, sonar frame), shape (n,): the elements'
        fields summed with their exact distances, R_T/R_e e^{−jk(R_e − R_T)} D_e, R_T from the
        transmitter's phase centre — the near field (a null of the far-field pattern is filled
        at a few Rayleigh distances), the far-field pattern far away."""
        p = np.asarray(points_m, float).reshape(-1, 3)
        d = p[:, None, :] - self.tx_center_m[None, :, :]                       # (n, n_t, 3)
        r_e = np.maximum(np.linalg.norm(d, axis=2), 1e-9)
        u = d / r_e[..., None]
        c, s = np.cos(self.tx_rotation_rad), np.sin(self.tx_rotation_rad)
        ux = u[..., 0] * c + u[..., 1] * s
        uy = -u[..., 0] * s + u[..., 1] * c
        dir_e = (np.sinc(0.5 * self.k * self.tx_size_m[:, 0] * ux / np.pi)
                 * np.sinc(0.5 * self.k * self.tx_size_m[:, 1] * uy / np.pi))
        dir_e = np.where(u[..., 2] < 0.0, 0.0, dir_e)
        r_t = np.maximum(np.linalg.norm(p - self._tx_ref, axis=1), 1e-9)[:, None]
        field = dir_e * (r_t / r_e) * np.exp(-1j * self.k * (r_e - r_t))
        return np.abs(field @ self.tx_weight) / np.abs(self.tx_weight.sum())

    def receive(self, directions):
        """|D(u)|: the receive elements' one-way pattern from ``directions`` (n, 3), shape (n,)."""
        u = self._unit(directions)
        return np.abs(self._pistons(u, self.rx_size_m, self.rx_rotation_rad).mean(axis=1))


def beam_pattern_of(tree, subarray: str = "A") -> BeamPattern:
    """The two-way pattern of a dataset's transmitter and the receive elements of ``subarray``.

    Raises
    ------
    processing.base.dataset.DatasetError
        The dataset lacks the element geometry (names the variables).
    """
    sonar = group_of(tree, SONAR_GROUP)
    need = ["tx_element_x", "tx_element_y", "tx_element_z", "tx_element_width",
            "tx_element_height", "tx_element_rotation", "tx_element_weight",
            "transmit_frequency_center"]
    missing = [f"/{SONAR_GROUP}/{k}" for k in need if sonar is None or k not in sonar]
    eg = group_of(tree, ELEMENT_GROUP)
    missing += [f"/{ELEMENT_GROUP}/{k}" for k in ("element_width", "element_height",
                                                  "element_rotation", "element_subarray")
                if eg is None or k not in eg]
    env = group_of(tree, ENVIRONMENT_GROUP)
    if env is None or "sound_speed_indicative" not in env:
        missing.append(f"/{ENVIRONMENT_GROUP}/sound_speed_indicative")
    if missing:
        raise DatasetError("target strength needs the sonar's element geometry: missing "
                           + ", ".join(missing) + " (docs/dataset.md)")
    sub = np.asarray(eg["element_subarray"].values).astype(str)
    rows = sub == subarray
    if not rows.any():
        raise DatasetError(f"target strength: no receive element of subarray {subarray!r} in "
                           f"/{ELEMENT_GROUP}/element_subarray (has {sorted(set(sub))})")
    k = 2 * np.pi * float(sonar["transmit_frequency_center"].values) / float(env["sound_speed_indicative"].values)
    return BeamPattern(
        np.stack([sonar[f"tx_element_{a}"].values for a in "xyz"], -1),
        np.stack([sonar["tx_element_width"].values, sonar["tx_element_height"].values], -1),
        sonar["tx_element_rotation"].values, sonar["tx_element_weight"].values,
        np.stack([eg["element_width"].values[rows], eg["element_height"].values[rows]], -1),
        eg["element_rotation"].values[rows], k)


def target_strength_db(amplitude_counts, range_m, positions_m, *, gain_counts_m: float,
                       absorption_db_per_m: float, pattern: BeamPattern, floor_db: float = -20.0):
    """Uncompensated and beam-compensated TS of detections.

    Parameters
    ----------
    amplitude_counts : array_like, shape (n,)
        Image peak |I| of each detection (counts).
    range_m : array_like, shape (n,)
        Range (m).
    positions_m : array_like, shape (n, 3)
        Located sonar-frame positions (m): their directions are the located angles.
    gain_counts_m : float
        G of the calibration (counts x m for a 1 m backscatter amplitude at 1 m on axis).
    absorption_db_per_m : float
    pattern : BeamPattern
    floor_db : float
        Two-way pattern below which no compensation is attempted (dB re axis).

    Returns
    -------
    ts_uncomp_db, ts_comp_db, pattern_db : ndarray, shape (n,)
        TS (dB re 1 m²) taken on axis, compensated at the located angles (NaN where the
        pattern is below ``floor_db`` or the amplitude is not positive), and the two-way
        pattern 20 log10(|E_t||D|) used (dB).
    """
    amp = np.asarray(amplitude_counts, float)
    r = np.asarray(range_m, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = amp * r * r * 10.0 ** (absorption_db_per_m * r / 10.0) / gain_counts_m
        ts_u = np.where(rho > 0, 20.0 * np.log10(np.where(rho > 0, rho, 1.0)), np.nan)
        b = pattern.two_way(positions_m)
        pat_db = np.where(b > 0, 20.0 * np.log10(np.where(b > 0, b, 1.0)), -np.inf)
    ts_c = np.where(pat_db >= floor_db, ts_u - pat_db, np.nan)
    return ts_u, ts_c, pat_db
