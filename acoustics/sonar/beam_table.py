"""The beam table of ``abacus beams``: transmitter and receiver, generic vs ABACUS layout.

Thesis reference values (Tables 3.2, 3.3 and the 10 dB widths of §3.3.8) travel with the
numbers so the table shows both side by side.
"""
from __future__ import annotations

import numpy as np

from acoustics.sonar.arrays import Receiver, abacus_receiver, abacus_transmitter, mode_channels
from acoustics.sonar.beams import summarize_beam
from acoustics.medium import Medium
from acoustics.sonar.cache import per_geometry

__all__ = ["THESIS_BEAMS", "beam_arrays", "beam_table", "format_beam_table"]

#: (array, variant, mode) -> thesis values (deg), §3.3.8 Tables 3.2 and 3.3
THESIS_BEAMS = {
    ("transmitter", "generic", "normal"): {"azimuth_3db_deg": 9.14, "elevation_3db_deg": 0.96},
    ("transmitter", "abacus", "normal"): {"azimuth_3db_deg": 10.28, "elevation_3db_deg": 0.86,
                                          "azimuth_10db_deg": 17.75, "elevation_10db_deg": 1.47},
    ("receiver", "generic", "normal"): {"azimuth_3db_deg": 0.78, "elevation_3db_deg": 9.33},
    ("receiver", "abacus", "normal"): {"azimuth_3db_deg": 0.78, "elevation_3db_deg": 8.80},
    ("receiver", "abacus", "interferometric"): {"azimuth_3db_deg": 1.56, "elevation_3db_deg": 8.80},
}


def beam_arrays(geometry: dict | None = None) -> dict:
    """The arrays the beam table describes: ``{(array, variant, mode): ElementArray}``.

    A receiver "mode" pattern is the pattern of one image's channels: all 16 elements of
    subarray A (normal), or the middle 8 of A (interferometric).
    ``geometry`` (PresetGeometry keys) applies to the abacus variant.
    """
    g = dict(geometry or {})
    out = {}
    for variant in ("generic", "abacus"):
        gg = g if variant == "abacus" else {}
        out[("transmitter", variant, "normal")] = abacus_transmitter(
            variant, stagger_m=gg.get("transmitter_stagger_m"),
            rotated_end_elements=gg.get("transmitter_rotated_end_elements"))
        subs = abacus_receiver(variant, stagger_m=gg.get("receiver_stagger_m"),
                               b_offset_m=gg.get("subarray_b_offset_m"),
                               **({"baseline_m": gg["baseline_m"]} if "baseline_m" in gg else {}))
        for mode in ("normal", "interferometric"):
            rx = Receiver(subs, mode_channels(mode), mode)
            first = next(iter(rx.image_groups.values()))
            out[("receiver", variant, mode)] = rx.elements.subset(first, f"receiver {mode}")
    return out


def beam_table(*, medium: Medium | None = None, frequency_hz: float | None = None,
               geometry: dict | None = None) -> dict:
    """Nested dict ``{array: {variant: {mode: numbers}}}`` with the DESIGN.md keys.

    A function of the geometry, the sound speed and the frequency only: computed once and kept
    in the geometry cache (:mod:`acoustics.sonar.cache`, memory and disk).
    """
    medium = medium or Medium()
    key = (tuple(sorted((geometry or {}).items())), float(medium.sound_speed_m_s),
           None if frequency_hz is None else float(frequency_hz))

    def compute():
        out: dict = {}
        for (array, variant, mode), arr in beam_arrays(geometry).items():
            s = summarize_beam(arr, medium=medium, frequency_hz=frequency_hz)
            out.setdefault(array, {}).setdefault(variant, {})[mode] = s.as_dict()
        return out
    return per_geometry("beam_table", key, compute)


def format_beam_table(table: dict) -> str:
    """Fixed-width text of :func:`beam_table` with the thesis' values alongside."""
    head = (f"{'array':<12}{'variant':<9}{'mode':<16}{'az 3dB':>8}{'el 3dB':>8}{'az 10dB':>9}"
            f"{'el 10dB':>9}{'PSL az':>8}{'PSL el':>8}   thesis (az 3dB, el 3dB, az 10dB, el 10dB)")
    lines = [head, "-" * len(head)]

    def f(x, w=8, p=3):
        return f"{'-':>{w}}" if x is None else f"{x:>{w}.{p}f}"

    for array, variants in table.items():
        for variant, modes in variants.items():
            for mode, v in modes.items():
                ref = THESIS_BEAMS.get((array, variant, mode), {})
                refs = ", ".join(f"{ref[k]:g}" if k in ref else "-" for k in
                                 ("azimuth_3db_deg", "elevation_3db_deg", "azimuth_10db_deg",
                                  "elevation_10db_deg"))
                lines.append(f"{array:<12}{variant:<9}{mode:<16}{f(v['azimuth_3db_deg'])}"
                             f"{f(v['elevation_3db_deg'])}{f(v['azimuth_10db_deg'], 9)}"
                             f"{f(v['elevation_10db_deg'], 9)}"
                             f"{f(v['azimuth_peak_sidelobe_db'], 8, 1)}"
                             f"{f(v['elevation_peak_sidelobe_db'], 8, 1)}   ({refs})")
    lines.append("widths in degrees (one-way, far field); PSL = peak sidelobe in dB re the "
                 "main lobe (grating lobes included)")
    return "\n".join(lines)


def beam_cuts(arrays: dict, *, medium: Medium | None = None, frequency_hz: float | None = None,
              span_deg: float = 30.0, n: int = 3001) -> dict:
    """Normalised principal cuts in dB for plotting: ``{key: {plane: (deg, dB)}}``."""
    from acoustics.sonar.beams import pattern_cut
    a = np.radians(np.linspace(-span_deg, span_deg, n))
    out = {}
    for key, arr in arrays.items():
        out[key] = {}
        for plane in ("azimuth", "elevation"):
            _, mag = pattern_cut(arr, plane=plane, angles_rad=a, medium=medium,
                                 frequency_hz=frequency_hz)
            db = 20 * np.log10(np.maximum(mag / mag.max(), 1e-6))
            out[key][plane] = (np.degrees(a), db)
    return out
