"""Per-arrival ground truth: one row per path of a ping (opt-in: ``effects.arrivals``).

Every echo abacus synthesises is a *virtual scatterer* (acoustics/synthesis/scatterers.py): a
transmit leg from the transmitter's phase centre T to p_tx and a receive leg from p_rx to the
receiver's phase centre R (a bounced leg is unfolded: p is the image point, the leg length
the unfolded length). This module turns a ping's scatterers into a table:

    delay        τ = (|p_tx − T| + |p_rx − R|) / c
    amplitude    a = q g(r1) g(r2) e^{−jk(r1 + r2)}, g(r) = 10^(−α r/20) / r (as the scene sets
                 spreading and absorption), q the path's strength (m; reflection coefficients
                 and a curved mirror's divergence included): the pressure at R re the source
                 level at 1 m, without the sonar's own directivities (which the
                 per-element synthesis adds: k S E_t(p_tx) D_n(p_rx))
    level        20 log10 |a| (dB)
    departure    the direction of p_tx from T; arrival: of p_rx from R (az, el, sonar frame)
    Doppler      −f0 (dL/dt) / c of the path (0 where the scene has no Doppler)

The interaction sequence is written in propagation order, ``-``-joined, from the alphabet
T (point target), S / F / O (specular bounce off a surface, floor, obstacle boundary),
RS / RF / RO (a surface, floor or obstacle facet's backscatter: reverberation), M (a mesh
target's facet).
"""
from __future__ import annotations

import numpy as np

from acoustics.frames import cartesian_to_spherical
from acoustics.synthesis.scatterers import PathTags, VirtualScatterers

__all__ = ["ALPHABET", "arrival_table", "direct_tags", "concat_tables", "COLUMNS"]

#: the interaction alphabet of ``arrival_sequence``
ALPHABET = {"T": "point target", "S": "specular bounce off a surface boundary",
            "F": "specular bounce off a floor boundary", "O": "specular bounce off an obstacle",
            "RS": "a surface facet's backscatter (reverberation)",
            "RF": "a floor facet's backscatter (reverberation)",
            "RO": "an obstacle facet's backscatter (reverberation)", "M": "a mesh target's facet"}

#: column -> dtype of a ping's table (the /Vendor_specific/Arrivals variables without ``arrival_``)
COLUMNS = {"ping_index": np.int64, "target_id": np.int64, "sequence": str, "scatterer": str,
           "boundary": str, "facet": np.int64, "via": str, "bounces": np.int64,
           "delay": float, "transmit_range": float, "receive_range": float, "level": float,
           "amplitude_r": float, "amplitude_i": float, "departure_azimuth": float,
           "departure_elevation": float, "azimuth": float, "elevation": float,
           "doppler": float, "shadowed": np.int8}


def direct_tags(rows) -> PathTags:
    """Tags of direct echoes: the targets' rows ``rows`` (int, shape (k,)), sequence ``T``."""
    rows = np.asarray(rows, np.int64)
    return PathTags(rows, np.full(rows.size, "T"), np.full(rows.size, ""))


def _facets(rs, view, p_tx):
    """(mesh index, facet) of facet scatterers at ``p_tx`` (ping sonar frame), from a ray cast
    from the transmitter to each (the facet it meets first is the one the point lies on)."""
    n = p_tx.shape[0]
    if rs is None or n == 0:
        return np.full(n, -1), np.full(n, -1)
    tx_c = rs.tx_center if view is None else view.to_world(rs.tx_center)
    pts = p_tx if view is None else view.to_world(p_tx)
    d = pts - tx_c
    hits = rs.caster.first_hit(np.broadcast_to(tx_c, pts.shape), d, purpose="arrivals")
    mesh = np.where(hits.hit, hits.mesh, -1).astype(np.int64)
    first = np.array([rs.caster.first_face(i) for i in range(len(rs.meshes))] or [0])
    face = np.where(mesh >= 0, hits.face - first[np.maximum(mesh, 0)], -1).astype(np.int64)
    return mesh, face


def arrival_table(setup, ping: int, vs: VirtualScatterers, targets, doppler_hz,
                  ray_scene=None, view=None) -> dict:
    """One ping's arrivals as columns (:data:`COLUMNS`), strongest first.

    Parameters
    ----------
    setup : Setup
        Its echo model and medium; ``effects.arrivals_floor_db`` drops arrivals more than that
        far below the strongest.
    ping : int
    vs : VirtualScatterers, length S
        Every path of the ping, with its :class:`PathTags` (facets may come untagged).
    targets : TargetSet
        The ping's targets (ids; ``shadowed``).
    doppler_hz : ndarray, shape (S,), or None
    ray_scene, view
        The ping's ray scene and view (to name the facets of facet scatterers).

    Returns
    -------
    dict of str to ndarray, each shape (k,)
        k ≤ S rows: paths of zero amplitude carry nothing and are left out.
    """
    model, medium = setup.model, setup.medium
    n = len(vs)
    tags = vs.tags if vs.tags is not None else PathTags.unknown(n)
    t_c = model.transmitter.phase_center_m
    r_c = model.receiver.phase_center_m
    d1, d2 = vs.p_tx - t_c, vs.p_rx - r_c
    r1, az1, el1 = cartesian_to_spherical(d1)
    r2, az2, el2 = cartesian_to_spherical(d2)
    g = medium.one_way_gain(r1, spreading=model.spreading, absorption=model.absorption) \
        * medium.one_way_gain(r2, spreading=model.spreading, absorption=model.absorption)
    k = model.wavenumber_rad_m
    amp = np.asarray(vs.strength, complex) * g * np.exp(-1j * k * (r1 + r2))
    mag = np.abs(amp)
    with np.errstate(divide="ignore"):
        level = 20 * np.log10(np.where(mag > 0, mag, 1.0))
    keep = mag > 0
    floor = setup.effects.arrivals_floor_db
    if floor is not None and keep.any():
        keep &= level >= level[keep].max() + floor
    seq = np.array(tags.sequence, dtype=object)
    via = np.array(tags.via, dtype=object)
    boundary = np.full(n, "", dtype=object)
    facet = np.full(n, -1, np.int64)
    facets = (seq == "") & np.isin(vs.kind, ("reverberation", "mesh_target")) & keep
    if facets.any():
        mesh, face = _facets(ray_scene, view, vs.p_tx[facets])
        names = np.array([sm.name for sm in ray_scene.meshes] + [""], dtype=object)
        # a boundary facet: R and the boundary's role (RS, RF, RO); a mesh target's: M
        roles = np.array(["R" + sm.role[0].upper() if sm.kind == "boundary" else "M"
                          for sm in ray_scene.meshes] + ["R"], dtype=object)
        boundary[facets] = names[mesh]
        facet[facets] = face
        seq[facets] = roles[mesh]
    tgt = np.asarray(tags.target, np.int64)
    is_t = tgt >= 0
    ids = targets.target_id if targets.target_id is not None else np.arange(len(targets))
    tid = np.full(n, -1, np.int64)
    tid[is_t] = np.asarray(ids, np.int64)[tgt[is_t]]
    shadow = np.zeros(n, np.int8)
    if targets.shadowed is not None:
        shadow[is_t] = np.asarray(targets.shadowed, bool)[tgt[is_t]]
    scatterer = np.where(is_t, np.char.add("target ", tid.astype(str)).astype(object),
                         np.char.add(np.char.add(boundary.astype(str), "#"), facet.astype(str)).astype(object))
    bounces = np.array([sum(c in "SFO" for c in s.split("-")) for s in seq], np.int64)
    dop = np.zeros(n) if doppler_hz is None else np.asarray(doppler_hz, float)
    order = np.flatnonzero(keep)[np.argsort(-level[keep], kind="stable")]
    cols = {"ping_index": np.full(n, int(ping), np.int64), "target_id": tid,
            "sequence": seq, "scatterer": scatterer, "boundary": boundary, "facet": facet,
            "via": via, "bounces": bounces, "delay": (r1 + r2) / medium.sound_speed_m_s,
            "transmit_range": r1, "receive_range": r2, "level": level,
            "amplitude_r": amp.real, "amplitude_i": amp.imag, "departure_azimuth": az1,
            "departure_elevation": el1, "azimuth": az2, "elevation": el2, "doppler": dop,
            "shadowed": shadow}
    return {c: np.asarray(v[order]).astype(COLUMNS[c]) for c, v in cols.items()}


def concat_tables(tables) -> dict:
    """The rows of several pings' tables, one after another (empty columns without any)."""
    return {c: (np.concatenate([t[c] for t in tables]) if tables else np.zeros(0, dt)).astype(dt)
            for c, dt in COLUMNS.items()}
