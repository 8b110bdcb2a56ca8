"""``abacus beams``: beamwidths and sidelobes of the transmitter and receiver, generic vs ABACUS."""
from __future__ import annotations

import json
from pathlib import Path

from abacus.cli.common import default_scene_path, load

HELP = "beamwidth and sidelobe table, beam-pattern plots"


def add_parser(sub):
    b = sub.add_parser("beams", help=HELP)
    b.add_argument("scene", nargs="?", help="scene file or built-in scene (default: default)")
    b.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    b.add_argument("--plots", metavar="DIR", help="write PNG plots into DIR")
    b.set_defaults(func=command)


def _geometry(scene):
    from acoustics.medium import Medium
    geometry = (scene.sonar.preset_geometry.model_dump()
                if scene.sonar.preset == "abacus" and scene.sonar.variant == "abacus" else None)
    return Medium.from_spec(scene.medium), scene.signal.center_frequency_hz, geometry


def beam_numbers(scene) -> dict:
    """The beam table of a scene's sonar (cached per geometry)."""
    from acoustics.sonar.beam_table import beam_table
    medium, f0, geometry = _geometry(scene)
    return beam_table(medium=medium, frequency_hz=f0, geometry=geometry)


def beam_figures(scene, outdir: Path) -> list[Path]:
    """The beam-pattern figures of a scene's sonar (thesis Figs. 3.11, 3.15, 3.17).

    They depend on the geometry alone, so the PNGs themselves are kept in the geometry cache
    (:mod:`acoustics.sonar.cache`): a second run copies them instead of drawing them.
    """
    import tempfile

    from abacus.figures.beams import plot_beam_figures
    pngs = cached_beam_figures(scene)
    if pngs is None:
        with tempfile.TemporaryDirectory() as tmp:
            plot_beam_figures(beam_cuts_of(scene), tmp)
            pngs = store_beam_figures(scene, tmp)
    return write_beam_figures(pngs, outdir)


def _figure_key(scene):
    from abacus.figures.beams import BEAM_FIGURE_STYLE
    medium, f0, geometry = _geometry(scene)
    return (tuple(sorted((geometry or {}).items())), float(medium.sound_speed_m_s), float(f0),
            BEAM_FIGURE_STYLE)


def beam_cuts_of(scene) -> dict:
    """What the beam figures draw: the pattern cuts of every array of the beam table."""
    from acoustics.sonar.beam_table import beam_arrays, beam_cuts
    medium, f0, geometry = _geometry(scene)
    return beam_cuts(beam_arrays(geometry), medium=medium, frequency_hz=f0)


def cached_beam_figures(scene):
    """The beam figures' PNG bytes (one uint8 array each) from the geometry cache, or None."""
    from acoustics.sonar.cache import cached
    return cached("beam_figures", _figure_key(scene))


def store_beam_figures(scene, folder) -> tuple:
    """Keep the beam figures drawn into ``folder`` in the geometry cache; returns their bytes."""
    import numpy as np

    from acoustics.sonar.cache import per_geometry
    from abacus.figures.beams import BEAM_FIGURES
    pngs = tuple(np.frombuffer((Path(folder) / name).read_bytes(), np.uint8) for name in BEAM_FIGURES)
    return per_geometry("beam_figures", _figure_key(scene), lambda: pngs)


def write_beam_figures(pngs, outdir) -> list[Path]:
    """Write the beam figures' PNG bytes into ``outdir`` (each file atomically)."""
    from abacus.figures.beams import BEAM_FIGURES
    from processing.base.atomic import write_bytes_atomic
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    return [write_bytes_atomic(outdir / name, np_bytes.tobytes())
            for name, np_bytes in zip(BEAM_FIGURES, pngs)]


def beams(scene, outdir: Path | None, as_json: bool) -> dict:
    """Print the beam table of a scene's sonar (and write plots into ``outdir``)."""
    from acoustics.sonar.beam_table import format_beam_table
    medium, f0, _ = _geometry(scene)
    table = beam_numbers(scene)
    if as_json:
        print(json.dumps(table, indent=2))
    else:
        print(f"Beam patterns at f0 = {f0 / 1e3:g} kHz, c = {medium.sound_speed_m_s:g} m/s "
              f"(λ = {medium.sound_speed_m_s / f0 * 1e3:.4g} mm)")
        print(format_beam_table(table))
    if outdir is not None:
        paths = beam_figures(scene, outdir)
        if not as_json:
            for p in paths:
                print(f"wrote {p}")
    return table


def command(args) -> int:
    scene = load(args.scene or default_scene_path())
    beams(scene, Path(args.plots) if args.plots else None, args.json)
    return 0
