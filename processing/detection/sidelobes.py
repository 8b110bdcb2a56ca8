"""Which detections of a ping are the imaging chain's response to a stronger one, not echoes.

A strong echo at physical levels (a fish on axis 80–90 dB above the noise) crosses the detection
threshold far outside its own resolution cell, along the two axes of the imaging chain's
point-spread function:

* **in range, in its own beam** — the compressed LFM pulse's range sidelobes, −40 to −50 dB near
  the main lobe (the Hamming range window's) and −70 to −80 dB out to the pulse's whole length,
  c T / 2 either side (5.2 m for ABACUS' 7 ms pulse); interferometry gives each a phase, so some
  are placed inside the counting volume;
* **across azimuth, at its range** — the spatial window's azimuth sidelobes, 20–35 dB down, within
  the range main lobe (± 2.5 range cells, the rule of
  :func:`processing.backscatter.single_targets.single_targets`);
* **at its grating-ghost azimuth, at its range** — a receiver subarray of pitch d whose alternate
  elements are offset ±δ across the array (staggered) images a target at elevation φ also at
  sin θ ± λ / (2 d) (±7° for ABACUS), |tan(k δ sin φ)| below it (−24 dB at 1°, −9 dB at 3°;
  thesis §4.5.6, docs/validation.md's Ghosts); a plain subarray at sin θ ± λ / d, at the
  target's level. A fish beside the fan in elevation is not counted, but its ghost has a phase of
  its own and interferometry may place it inside the volume; and a target beyond the span
  (ABACUS' receivers: its grating lobe at sin θ ± λ / d, ±14°) at the target's level.

A real fish inside the counting volume is inside the transmitter's main lobe, so its echo is at
most a few dB below axis, and fish of one school differ in TS by a few dB (tilt): a detection
more than ``sidelobe_db`` (default 30 dB) below a stronger detection of its ping, inside that
one's range or azimuth response, is taken for that response. At the ghost azimuth the level is
predicted from the stronger detection's own interferometric elevation: a detection no more than
``ghost_db`` (default 6 dB) above that prediction is its ghost. The price: a real fish that much
weaker, in a stronger one's beam within a pulse length, at its range, or at its range and ghost
azimuth, is not counted.
"""
from __future__ import annotations

import numpy as np

__all__ = ["psf_sidelobes", "ghost_geometry", "counted_sidelobes"]

#: range main lobe and near sidelobes of the windowed compressed pulse, in range resolution cells
NEAR_RANGE_CELLS = 2.5
#: azimuth main lobe half-width of a beam, in azimuth resolution cells (3 dB widths)
BEAM_CELLS = 1.5
#: how close (azimuth resolution cells, in sin θ) a detection must lie to a predicted ghost
GHOST_CELLS = 0.5


def psf_sidelobes(ping_rows, range_m, azimuth_rad, amplitude, *, range_resolution_m: float,
                  azimuth_resolution_rad: float, pulse_range_m: float, sidelobe_db: float,
                  elevation_rad=None, ghosts=(), ghost_db: float = 0.0):
    """Detections that lie in the point-spread response of a stronger detection of their ping.

    Detection j is a sidelobe of a stronger detection i of the same ping when i is more than
    ``sidelobe_db`` stronger and j lies

    * within ``NEAR_RANGE_CELLS`` range cells of i, at any azimuth (azimuth sidelobes, near range
      sidelobes), or
    * within ``BEAM_CELLS`` azimuth cells of i and within ``pulse_range_m`` in range (the
      compressed pulse's range sidelobes in i's beam);

    and it is i's ghost when it lies within ``NEAR_RANGE_CELLS`` range cells of i, within
    ``GHOST_CELLS`` azimuth cells of sin θ_i ± p for a ghost (p, k δ) of ``ghosts``, and its
    amplitude is at most ``ghost_db`` above that ghost's predicted level,
    A_i min(1, |tan(k δ sin φ_i)|) (A_i where k δ is None).

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
        less: no sidelobe rule (the reference: every detection counted).
    elevation_rad : array_like, shape (n,), optional
        Interferometric elevation (rad) of each detection, for the ghost level; without it (or
        where NaN) a ghost is predicted at the stronger detection's own level.
    ghosts : sequence of (float, float or None)
        The receiver's ghosts (:func:`ghost_geometry`): offset p in sin θ and k δ (rad; the
        ghost's level is |tan(k δ sin φ)| re its target; None: the target's level, a grating
        lobe). Empty: no ghost rule.
    ghost_db : float
        Margin (dB) above the predicted ghost level; 0 or less: no ghost rule.

    Returns
    -------
    ndarray of bool, shape (n,)
        True where the detection is taken for a stronger one's sidelobe or ghost. Non-finite
        amplitudes or positions are never stronger and never marked.
    """
    rows = np.asarray(ping_rows, int)
    r = np.asarray(range_m, float)
    az = np.asarray(azimuth_rad, float)
    a = np.asarray(amplitude, float)
    out = np.zeros(rows.size, bool)
    ghosts = [(float(p), ph) for p, ph in ghosts if p > 0] if ghost_db > 0 else []
    if (sidelobe_db <= 0 and not ghosts) or rows.size < 2:
        return out
    ratio = 10.0 ** (sidelobe_db / 20.0) if sidelobe_db > 0 else np.inf
    el = np.asarray(elevation_rad, float) if elevation_rad is not None else np.full(rows.size, np.nan)
    ghost_amp = []          # per ghost: the largest amplitude its ghost may have, shape (n,)
    for _, phase in ghosts:
        level = np.ones(rows.size)
        if phase is not None:
            with np.errstate(invalid="ignore"):
                lv = np.abs(np.tan(phase * np.sin(el)))
            level = np.where(np.isfinite(lv), np.minimum(lv, 1.0), 1.0)
        ghost_amp.append(a * level * 10.0 ** (ghost_db / 20.0))
    finite = np.isfinite(a) & np.isfinite(r) & np.isfinite(az)
    order = np.argsort(rows, kind="stable")
    bounds = np.flatnonzero(np.diff(rows[order])) + 1
    for k in np.split(order, bounds):
        k = k[finite[k]]
        if k.size < 2:
            continue
        dr = np.abs(r[k][:, None] - r[k][None, :])
        daz = np.abs(az[k][:, None] - az[k][None, :])
        near = dr <= NEAR_RANGE_CELLS * range_resolution_m
        # i (rows) far above j (columns)
        far_above = a[k][:, None] > ratio * a[k][None, :]
        in_beam = (daz <= BEAM_CELLS * azimuth_resolution_rad) & (dr <= max(pulse_range_m, 0.0))
        hit = far_above & (near | in_beam)
        if ghosts:
            dsin = np.abs(np.sin(az[k])[None, :] - np.sin(az[k])[:, None])
            stronger = a[k][:, None] > a[k][None, :]
            for (period, _), amp in zip(ghosts, ghost_amp):
                at_ghost = np.abs(dsin - period) <= GHOST_CELLS * azimuth_resolution_rad
                hit |= near & at_ghost & stronger & (a[k][None, :] <= amp[k][:, None])
        out[k] = np.any(hit, axis=0)
    return out


def ghost_geometry(element_position_m, wavelength_m: float) -> list:
    """The ghosts of a line subarray along the sonar's x axis: offsets in sin θ and levels.

    Parameters
    ----------
    element_position_m : array_like, shape (n, 3)
        The subarray's element positions (m, sonar frame: x along the array, y across it).
    wavelength_m : float

    Returns
    -------
    list of (float, float or None)
        (offset in sin θ, k δ): for a staggered subarray (alternate elements offset ±δ across
        it) the stagger's ghost (λ / (2 d), k δ: |tan(k δ sin φ)| below a target at elevation φ)
        and the grating lobe (λ / d, None: at the target's level); for a plain one the grating
        lobe only; empty for fewer than two elements or a non-finite geometry.
    """
    pos = np.asarray(element_position_m, float).reshape(-1, 3)
    if pos.shape[0] < 2 or not np.all(np.isfinite(pos)) or not wavelength_m > 0:
        return []
    order = np.argsort(pos[:, 0])
    x, y = pos[order, 0], pos[order, 1]
    d = float(np.median(np.diff(x)))
    if not d > 0:
        return []
    half_offset = 0.5 * abs(float(np.mean(y[0::2]) - np.mean(y[1::2]))) if pos.shape[0] >= 4 else 0.0
    if half_offset > 1e-3 * d:
        return [(float(wavelength_m / (2 * d)), float(2 * np.pi / wavelength_m * half_offset)),
                (float(wavelength_m / d), None)]
    return [(float(wavelength_m / d), None)]


def counted_sidelobes(table: dict, record, count_settings, *, range_resolution_m: float,
                      azimuth_resolution_rad: float, image_group: str = "A") -> np.ndarray:
    """The detections the count leaves out as sidelobes or ghosts (``count.sidelobe_db``,
    ``count.ghost_db``), with the pulse's range extent and the ghosts from the record.

    Parameters
    ----------
    table : dict of ndarray, each shape (n,)
        Detections: ``ping``, ``range_m``, ``azimuth_rad``, ``amplitude``, ``elevation_rad``.
    record : SonarRecord
        Its ``replica``, ``rate_hz``, ``sound_speed_m_s``, ``center_frequency_hz``,
        ``element_position_m`` and ``element_subarray`` (the pulse and the receiver geometry).
    count_settings : processing.settings.CountSettings
    range_resolution_m, azimuth_resolution_rad : float
    image_group : str
        The subarray the detections were made on.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    n = len(table["ping"])
    cs = count_settings
    if (cs.sidelobe_db <= 0 and cs.ghost_db <= 0) or n < 2:
        return np.zeros(n, bool)
    c = float(record.sound_speed_m_s)
    taps = int(np.count_nonzero(np.abs(np.asarray(record.replica)) > 0))
    pulse_range_m = taps / record.rate_hz * c / 2 if taps and record.rate_hz > 0 else 0.0
    pos = np.asarray(record.element_position_m, float)
    sel = np.asarray(record.element_subarray).astype(str) == image_group
    ghosts = ghost_geometry(pos[sel] if sel.sum() >= 2 else pos, c / float(record.center_frequency_hz))
    return psf_sidelobes(table["ping"], table["range_m"], table["azimuth_rad"], table["amplitude"],
                         range_resolution_m=range_resolution_m, azimuth_resolution_rad=azimuth_resolution_rad,
                         pulse_range_m=pulse_range_m, sidelobe_db=cs.sidelobe_db,
                         elevation_rad=table.get("elevation_rad"), ghosts=ghosts, ghost_db=cs.ghost_db)
