"""The motion part of the tracker: how a track's state moves between pings and takes in a detection.

Two filters over the state [x, y, z, vx, vy, vz] (m, m/s, world frame), interchangeable in the
tracker (:func:`processing.tracking.filters.track_detections`, setting ``track.method``):

* :class:`ConstantVelocityKalman` — white-noise-acceleration constant-velocity Kalman filter
  (Bar-Shalom, Li & Kirubarajan 2001, §6.2.2) with Rauch–Tung–Striebel smoothing (Särkkä 2013,
  §8.2);
* :class:`AlphaBeta` — the thesis' αβ filter (§7): fixed gains, its gate the measurement
  covariance plus the spread a speed of ``speed_sd_m_s`` gives over the interval.

Both expose ``predict``, ``innovation_covariance``, ``update`` and ``smooth``; nothing else of
the tracker depends on which one runs.
"""
from __future__ import annotations

import numpy as np

__all__ = ["cv_matrices", "ConstantVelocityKalman", "AlphaBeta", "motion_model"]

_H = np.hstack([np.eye(3), np.zeros((3, 3))])


def cv_matrices(dt_s: float, accel_sd_m_s2: float):
    """Constant-velocity transition F (6, 6) and process noise Q (6, 6) for a white-noise
    acceleration of spectral density q = accel_sd² (m²/s³ per axis) over dt (s):
    Q = q [[dt³/3, dt²/2], [dt²/2, dt]] ⊗ I₃ (Bar-Shalom, Li & Kirubarajan 2001, §6.2.2)."""
    dt = float(dt_s)
    eye = np.eye(3)
    F = np.block([[eye, dt * eye], [np.zeros((3, 3)), eye]])
    q = accel_sd_m_s2 ** 2
    Q = q * np.block([[dt**3 / 3 * eye, dt**2 / 2 * eye], [dt**2 / 2 * eye, dt * eye]])
    return F, Q


class ConstantVelocityKalman:
    """Constant-velocity Kalman filter.

    Parameters
    ----------
    accel_sd_m_s2 : float
        Process noise: white acceleration of spectral density accel_sd² (m²/s³ per axis).
    """

    name = "kalman"

    def __init__(self, accel_sd_m_s2: float = 0.1):
        self.accel_sd_m_s2 = float(accel_sd_m_s2)

    def predict(self, x, P, dt_s):
        """State (6,) and covariance (6, 6) predicted ``dt_s`` (s) ahead."""
        F, Q = cv_matrices(dt_s, self.accel_sd_m_s2)
        return F @ x, F @ P @ F.T + Q

    def innovation_covariance(self, P_pred, R, dt_s):
        """Covariance (…, 3, 3) (m²) of a detection's innovation: the predicted position's
        covariance plus the detection's own ``R`` (…, 3, 3)."""
        return P_pred[:3, :3] + R

    def update(self, x_pred, P_pred, z, R, dt_s):
        """The state (6,) and covariance (6, 6) after taking in a detection at ``z`` (3,) (m)
        with covariance ``R`` (3, 3) (m²); Joseph form, so P stays symmetric."""
        K = P_pred @ _H.T @ np.linalg.inv(P_pred[:3, :3] + R)
        x = x_pred + K @ (z - x_pred[:3])
        IKH = np.eye(6) - K @ _H
        return x, IKH @ P_pred @ IKH.T + K @ R @ K.T

    def update_mixture(self, x_pred, P_pred, z, R, weights, dt_s):
        """The probabilistic-data-association update (Bar-Shalom & Li 1995, §6.4): the state
        after detections ``z`` (k, 3) each with probability ``weights`` (k,) of being this
        track's (1 − Σw: none is), their covariances ``R`` (k, 3, 3) averaged with the same
        weights. Returns the state (6,) and covariance (6, 6), spread of innovations included."""
        w = np.asarray(weights, float)
        b0 = max(0.0, 1.0 - w.sum())
        Rm = np.einsum("k,kij->ij", w, R) / max(w.sum(), 1e-300)
        S = P_pred[:3, :3] + Rm
        K = P_pred @ _H.T @ np.linalg.inv(S)
        nu = z - x_pred[:3]
        nu_c = w @ nu
        x = x_pred + K @ nu_c
        Pc = P_pred - K @ S @ K.T
        spread = np.einsum("k,ki,kj->ij", w, nu, nu) - np.outer(nu_c, nu_c)
        P = b0 * P_pred + (1 - b0) * Pc + K @ spread @ K.T
        return x, 0.5 * (P + P.T)

    def smooth(self, xs, Ps, xs_pred, Ps_pred, times):
        """Rauch–Tung–Striebel smoothed states, a list of (6,) arrays, one per ping."""
        n = len(xs)
        out = [None] * n
        Ps_s = [None] * n
        out[-1], Ps_s[-1] = xs[-1].copy(), Ps[-1].copy()
        for k in range(n - 2, -1, -1):
            F, _ = cv_matrices(times[k + 1] - times[k], self.accel_sd_m_s2)
            Pp = Ps_pred[k + 1]
            G = Ps[k] @ F.T @ np.linalg.pinv(Pp)
            out[k] = xs[k] + G @ (out[k + 1] - xs_pred[k + 1])
            Ps_s[k] = Ps[k] + G @ (Ps_s[k + 1] - Pp) @ G.T
        return out


class AlphaBeta:
    """The αβ filter: fixed gains on the position and velocity.

    Parameters
    ----------
    alpha, beta : float
        Position and velocity gains.
    speed_sd_m_s : float
        The gate's allowance for motion: a detection's innovation covariance is 2R plus
        (speed_sd·dt)² I.
    """

    name = "alpha_beta"

    def __init__(self, alpha: float = 0.5, beta: float = 0.2, speed_sd_m_s: float = 0.5):
        self.alpha, self.beta, self.speed_sd_m_s = float(alpha), float(beta), float(speed_sd_m_s)

    def predict(self, x, P, dt_s):
        F, _ = cv_matrices(dt_s, 0.0)
        return F @ x, P

    def innovation_covariance(self, P_pred, R, dt_s):
        return 2 * R + (self.speed_sd_m_s * dt_s) ** 2 * np.eye(3)

    def update(self, x_pred, P_pred, z, R, dt_s):
        nu = z - x_pred[:3]
        x = x_pred.copy()
        x[:3] += self.alpha * nu
        x[3:] += self.beta * nu / max(dt_s, 1e-9)
        return x, P_pred

    def update_mixture(self, x_pred, P_pred, z, R, weights, dt_s):
        w = np.asarray(weights, float)
        return self.update(x_pred, P_pred, x_pred[:3] + w @ (z - x_pred[:3]), R[0], dt_s)

    def smooth(self, xs, Ps, xs_pred, Ps_pred, times):
        return [x.copy() for x in xs]


def motion_model(method: str, *, accel_sd_m_s2: float = 0.1, alpha: float = 0.5, beta: float = 0.2,
                 speed_sd_m_s: float = 0.5):
    """The filter named by the setting ``track.method``: "kalman" or "alpha_beta"."""
    if method == "kalman":
        return ConstantVelocityKalman(accel_sd_m_s2)
    if method == "alpha_beta":
        return AlphaBeta(alpha, beta, speed_sd_m_s)
    raise ValueError(f"tracking method must be 'kalman' or 'alpha_beta', got {method!r}")
