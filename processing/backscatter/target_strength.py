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

**Near field.** The far-field pattern is the limit of an infinitely distant target. ABACUS'
transmitter is 0.24 m tall (16 elements stacked in elevation): its Rayleigh distance L²/λ is
15.8 m at 420 kHz, inside the observation range (10.5–68 m). Closer than a few times that, the
element paths to a target on the axis differ by a sizeable fraction of a wavelength (the edge
element's excess path L²/(8r) is 0.1 λ at 20 m, 0.16 λ at 12 m) and their sum falls short of
the far-field sum: a loss of ≈ 53/r² dB on axis (0.37 dB at 12 m, 0.13 dB at 20 m, 0.03 dB at 40 m), the same
for CW and LFM because it is a property of the carrier's wavelength and the aperture. The
receive beamformer steers plane waves, so a receive aperture of length L_r loses the same way
(8 elements, interferometric mode: 0.01 dB at 12 m; 16 elements with the Hamming window,
normal mode: 0.16 dB at 12 m). :meth:`BeamPattern.near_field_db` computes both from the element geometry with each
element's exact path to the located position, and :func:`target_strength_db` compensates them
(``near_field=True``, the default; ``single_target.near_field`` in the settings). This was the
cause of compensated TS reading 0.1–0.4 dB low at 12–20 m (docs/single_targets.md).
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
    rx_center_m : ndarray, shape (n_r, 3), optional
        Centres of the receive elements of the image (m), for the receive beam's near field.
    rx_weight : ndarray, shape (n_r,), optional
        The beamformer's spatial window over them, in the order of ``rx_center_m`` sorted by x
        (as :class:`processing.imaging.beamforming.SubarrayGeometry` applies it).
    """

    def __init__(self, tx_center_m, tx_size_m, tx_rotation_rad, tx_weight, rx_size_m,
                 rx_rotation_rad, wavenumber_rad_m, rx_center_m=None, rx_weight=None):
        self.tx_center_m = np.asarray(tx_center_m, float).reshape(-1, 3)
        self.tx_size_m = np.asarray(tx_size_m, float).reshape(-1, 2)
        self.tx_rotation_rad = np.asarray(tx_rotation_rad, float).ravel()
        self.tx_weight = np.asarray(tx_weight, float).ravel()
        self.rx_size_m = np.asarray(rx_size_m, float).reshape(-1, 2)
        self.rx_rotation_rad = np.asarray(rx_rotation_rad, float).ravel()
        self.k = float(wavenumber_rad_m)
        self._tx_ref = (self.tx_center_m * np.abs(self.tx_weight)[:, None]).sum(0) / np.abs(self.tx_weight).sum()
        self.rx_center_m = None if rx_center_m is None else np.asarray(rx_center_m, float).reshape(-1, 3)
        self.rx_weight = (None if rx_weight is None else np.asarray(rx_weight, float).ravel())

    def _pistons(self, u, size, rotation):
        """sinc·sinc of each direction for each element (m,): ``u`` shape (n, 3) (one direction
        for all elements) or (n, m, 3) (one per element); result shape (n, m). np.sinc is 1 at 0
        (broadside exact), and nothing radiates behind the element plane."""
        if u.ndim == 2:
            u = u[:, None, :]
        c, s = np.cos(rotation), np.sin(rotation)
        ux = u[..., 0] * c + u[..., 1] * s
        uy = -u[..., 0] * s + u[..., 1] * c
        d = (np.sinc(0.5 * self.k * size[:, 0] * ux / np.pi)
             * np.sinc(0.5 * self.k * size[:, 1] * uy / np.pi))
        return np.where(u[..., 2] < 0.0, 0.0, d)

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
        u = np.asarray(directions, float).reshape(-1, 3)
        norm = np.linalg.norm(u, axis=1, keepdims=True)
        u = np.where(norm > 0, u / np.where(norm > 0, norm, 1.0), np.array([0.0, 0.0, 1.0]))
        phase = np.exp(1j * self.k * ((self.tx_center_m - self._tx_ref) @ u.T)).T    # (n, n_t)
        e_t = np.abs((self._pistons(u, self.tx_size_m, self.tx_rotation_rad) * phase)
                     @ self.tx_weight) / np.abs(self.tx_weight.sum())
        d = self._pistons(u, self.rx_size_m, self.rx_rotation_rad).mean(axis=1)
        return e_t * np.abs(d)

    def near_field_db(self, positions_m) -> np.ndarray:
        """The near field's share of the two-way pattern at located positions (dB, ≤ 0 near the
        axis): 20 log10 of the response with each element's exact path over the far-field
        response in the same direction, for the transmitter and (when the receive aperture is
        known) the receive beam.

        Transmitter: E(P) = Σ w_e D_e(û_e) e^{−jk(R_e − R_T)} (R_T / R_e) / Σ w_e, R_e the path
        from element e, û_e its direction (the model of docs/arrays.md at a finite range).
        Receive beam: the plane-wave beamformer's peak response over azimuth,
        max_θ |Σ w_n e^{−jk(R_n − R_c)} e^{−jk (x_n − x_c)·û(θ)}| / Σ w_n, over the same with
        far-field phases; the image's peak interpolation measures that maximum.

        Parameters
        ----------
        positions_m : array_like, shape (n, 3)
            Sonar-frame positions (m); a position at the array (range 0) gives 0 dB.

        Returns
        -------
        ndarray, shape (n,)
            dB; 0 in the far field.
        """
        p = np.asarray(positions_m, float).reshape(-1, 3)
        out = np.zeros(p.shape[0])
        r_t = np.linalg.norm(p - self._tx_ref, axis=1)
        ok = np.isfinite(r_t) & (r_t > 1e-3)
        if not ok.any():
            return out
        q = p[ok]
        r_ref = r_t[ok]
        u = (q - self._tx_ref) / r_ref[:, None]
        d = q[:, None, :] - self.tx_center_m[None]                    # (n, n_t, 3)
        r_e = np.linalg.norm(d, axis=-1)
        u_e = d / r_e[..., None]
        near = np.abs((self._pistons(u_e, self.tx_size_m, self.tx_rotation_rad)
                       * np.exp(-1j * self.k * (r_e - r_ref[:, None])) * (r_ref[:, None] / r_e))
                      @ self.tx_weight)
        phase = np.exp(1j * self.k * ((self.tx_center_m - self._tx_ref) @ u.T)).T
        far = np.abs((self._pistons(u, self.tx_size_m, self.tx_rotation_rad) * phase) @ self.tx_weight)
        with np.errstate(divide="ignore", invalid="ignore"):
            db = np.where((near > 0) & (far > 0), 20.0 * np.log10(near / np.where(far > 0, far, 1.0)), 0.0)
        if self.rx_center_m is not None and self.rx_center_m.shape[0] > 1:
            db = db + self._receive_near_field_db(q)
        out[ok] = db
        return out

    def _receive_near_field_db(self, q):
        x = self.rx_center_m[np.argsort(self.rx_center_m[:, 0], kind="stable")]
        w = self.rx_weight if self.rx_weight is not None else np.ones(x.shape[0])
        c = x.mean(axis=0)
        rel = x - c
        r_c = np.linalg.norm(q - c, axis=1)
        u = (q - c) / r_c[:, None]
        az = np.arctan2(u[:, 0], u[:, 2])
        # the peak over azimuth: a fine grid around the target's azimuth, ±0.3 beamwidths
        span = x[-1, 0] - x[0, 0]
        half = 0.3 * 2 * np.pi / (self.k * max(span, 1e-6))
        th = az[:, None] + np.linspace(-half, half, 61)[None, :]            # (n, g)
        steer = np.exp(-1j * self.k * (rel[None, None, :, 0] * np.sin(th)[..., None]
                                       + rel[None, None, :, 2] * np.cos(th)[..., None]))  # (n, g, m)
        r_n = np.linalg.norm(q[:, None, :] - x[None], axis=-1)             # (n, m)
        a_near = np.exp(-1j * self.k * (r_n - r_c[:, None]))
        a_far = np.exp(1j * self.k * (rel @ u.T).T)
        near = np.abs(np.einsum("ngm,nm,m->ng", steer, a_near, w)).max(axis=1)
        far = np.abs(np.einsum("ngm,nm,m->ng", steer, a_far, w)).max(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where((near > 0) & (far > 0), 20.0 * np.log10(near / np.where(far > 0, far, 1.0)), 0.0)


def beam_pattern_of(tree, subarray: str = "A", spatial_window: str | None = "hamming") -> BeamPattern:
    """The two-way pattern of a dataset's transmitter and the receive elements of ``subarray``
    (an image group: "A", "B", or "AB" for both, combined mode), with the receive aperture and
    the beamformer's ``spatial_window`` for the receive beam's near field (None: without it).

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
    rows = np.isin(sub, list(subarray)) if subarray == "AB" else sub == subarray
    if not rows.any():
        raise DatasetError(f"target strength: no receive element of subarray {subarray!r} in "
                           f"/{ELEMENT_GROUP}/element_subarray (has {sorted(set(sub))})")
    k = 2 * np.pi * float(sonar["transmit_frequency_center"].values) / float(env["sound_speed_indicative"].values)
    rx_center = rx_weight = None
    if spatial_window is not None and all(f"element_{a}" in eg for a in "xyz"):
        from processing.imaging.compression import window
        rx_center = np.stack([eg[f"element_{a}"].values[rows] for a in "xyz"], -1).astype(float)
        rx_weight = window(spatial_window, int(rows.sum()))
    return BeamPattern(
        np.stack([sonar[f"tx_element_{a}"].values for a in "xyz"], -1),
        np.stack([sonar["tx_element_width"].values, sonar["tx_element_height"].values], -1),
        sonar["tx_element_rotation"].values, sonar["tx_element_weight"].values,
        np.stack([eg["element_width"].values[rows], eg["element_height"].values[rows]], -1),
        eg["element_rotation"].values[rows], k, rx_center, rx_weight)


def target_strength_db(amplitude_counts, range_m, positions_m, *, gain_counts_m: float,
                       absorption_db_per_m: float, pattern: BeamPattern, floor_db: float = -20.0,
                       near_field: bool = True):
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
    near_field : bool
        Compensate the near field too (:meth:`BeamPattern.near_field_db`, at the located
        positions); False: the far-field pattern only, as echosounders compensate.

    Returns
    -------
    ts_uncomp_db, ts_comp_db, pattern_db : ndarray, shape (n,)
        TS (dB re 1 m²) taken on axis, compensated at the located angles (NaN where the
        pattern is below ``floor_db`` or the amplitude is not positive), and the two-way
        pattern 20 log10(|E_t||D|) used (dB), its near-field share included when
        ``near_field``.
    """
    amp = np.asarray(amplitude_counts, float)
    r = np.asarray(range_m, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = amp * r * r * 10.0 ** (absorption_db_per_m * r / 10.0) / gain_counts_m
        ts_u = np.where(rho > 0, 20.0 * np.log10(np.where(rho > 0, rho, 1.0)), np.nan)
        b = pattern.two_way(positions_m)
        pat_db = np.where(b > 0, 20.0 * np.log10(np.where(b > 0, b, 1.0)), -np.inf)
        if near_field and r.size:
            pat_db = pat_db + pattern.near_field_db(positions_m)
    ts_c = np.where(pat_db >= floor_db, ts_u - pat_db, np.nan)
    return ts_u, ts_c, pat_db
