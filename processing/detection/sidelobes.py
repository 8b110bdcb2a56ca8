"""Which detections of a ping are the imaging chain's response to a stronger one, not echoes.

A strong echo at physical levels (a fish on axis 80–90 dB above the noise) crosses the detection
threshold far outside its own resolution cell, along the two axes of the imaging chain's
point-spread function:

* **in range, in its own beam** — the compressed LFM pulse's range sidelobes, −40 to −50 dB near
  the main lobe (the Hamming range window's) and −70 to −80 dB out to the pulse's whole length,
  c T / 2 either side (5.2 m for ABACUS' 7 ms pulse); interferometry gives each a phase, so some
  are placed inside the counting volume;
* **across azimuth, at its range** — the spatial window's azimuth sidelobes and the receiver's
  grating ghosts, 20–35 dB down, within the range main lobe (± 2.5 range cells, the rule of
  :func:`processing.backscatter.single_targets.single_targets`).

A real fish inside the counting volume is inside the transmitter's main lobe, so its echo is at
most a few dB below axis, and fish of one school differ in TS by a few dB (tilt): a detection
more than ``sidelobe_db`` (default 30 dB) below a stronger detection of its ping, inside that
one's response, is taken for the response. The price: a real fish that much weaker, in a
stronger one's beam within a pulse length, or at its range, is not counted.
"""
from __future__ import annotations

import numpy as np

__all__ = ["psf_sidelobes"]

#: range main lobe and near sidelobes of the windowed compressed pulse, in range resolution cells
NEAR_RANGE_CELLS = 2.5
#: azimuth main lobe half-width of a beam, in azimuth resolution cells (3 dB widths)
BEAM_CELLS = 1.5


def psf_sidelobes(ping_rows, range_m, azimuth_rad, amplitude, *, range_resolution_m: float,
                  azimuth_resolution_rad: float, pulse_range_m: float, sidelobe_db: float):
    """Detections that lie in the point-spread response of a much stronger detection of their ping.

    Detection j is a sidelobe of a stronger detection i of the same ping when i is more than
    ``sidelobe_db`` stronger and j lies

    * within ``NEAR_RANGE_CELLS`` range cells of i, at any azimuth (azimuth sidelobes, grating
      ghosts, near range sidelobes), or
    * within ``BEAM_CELLS`` azimuth cells of i and within ``pulse_range_m`` in range (the
      compressed pulse's range sidelobes in i's beam).

    Parameters
    ----------
    ping_rows : array_like of int, shape (n,)
        Ping of each detection.
    range_m, azimuth_rad, amplitude : array_like, shape (n,)
        Range (m), azimuth (rad) and image peak (any linear amplitude unit) of each detection.
    range_resolution_m, azimuth_resolution_rad : float
        The images' range (m) and azimuth (rad) 3 dB resolution.
    pulse_range_m : float
        The compressed pulse's range extent either side of its peak, c T / 2 (m); 0 keeps only
        the near rule.
    sidelobe_db : float
        How much stronger (dB, amplitude ratio 20 log10) the stronger detection must be; 0 or
        less marks nothing (the reference: every detection counted).

    Returns
    -------
    ndarray of bool, shape (n,)
        True where the detection is taken for a stronger one's sidelobe. Non-finite amplitudes
        are never stronger and never marked.
    """
    rows = np.asarray(ping_rows, int)
    r = np.asarray(range_m, float)
    az = np.asarray(azimuth_rad, float)
    a = np.asarray(amplitude, float)
    out = np.zeros(rows.size, bool)
    if sidelobe_db <= 0 or rows.size < 2:
        return out
    ratio = 10.0 ** (sidelobe_db / 20.0)
    finite = np.isfinite(a) & np.isfinite(r) & np.isfinite(az)
    order = np.argsort(rows, kind="stable")
    bounds = np.flatnonzero(np.diff(rows[order])) + 1
    for k in np.split(order, bounds):
        k = k[finite[k]]
        if k.size < 2:
            continue
        dr = np.abs(r[k][:, None] - r[k][None, :])
        daz = np.abs(az[k][:, None] - az[k][None, :])
        # i (rows) far above j (columns)
        far_above = a[k][:, None] > ratio * a[k][None, :]
        near = dr <= NEAR_RANGE_CELLS * range_resolution_m
        in_beam = (daz <= BEAM_CELLS * azimuth_resolution_rad) & (dr <= max(pulse_range_m, 0.0))
        out[k] = np.any(far_above & (near | in_beam), axis=0)
    return out
