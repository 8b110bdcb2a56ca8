"""``abacus beams``: beamwidths and sidelobes of the transmitter and receiver, generic vs ABACUS."""
from __future__ import annotations

import json
from pathlib import Path

from acoustics.cli.common import default_scene_path, load

HELP = "beamwidth and sidelobe table, beam-pattern plots"


def add_parser(sub):
    b = sub.add_parser("beams", help=HELP)
    b.add_argument("scene", nargs="?", help="scene file or built-in scene (default: default)")
    b.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    b.add_argument("--plots", metavar="DIR", help="write PNG plots into DIR")
    b.set_defaults(func=command)


def beams(scene, outdir: Path | None, as_json: bool) -> dict:
    """Print the beam table of a scene's sonar (and write plots into ``outdir``)."""
    from acoustics.medium import Medium
    from acoustics.sonar.beam_table import beam_arrays, beam_cuts, beam_table, format_beam_table
    medium = Medium.from_spec(scene.medium)
    f0 = scene.signal.center_frequency_hz
    geometry = (scene.sonar.preset_geometry.model_dump()
                if scene.sonar.preset == "abacus" and scene.sonar.variant == "abacus" else None)
    table = beam_table(medium=medium, frequency_hz=f0, geometry=geometry)
    if as_json:
        print(json.dumps(table, indent=2))
    else:
        print(f"Beam patterns at f0 = {f0 / 1e3:g} kHz, c = {medium.sound_speed_m_s:g} m/s "
              f"(λ = {medium.sound_speed_m_s / f0 * 1e3:.4g} mm)")
        print(format_beam_table(table))
    if outdir is not None:
        from acoustics.sonar.plots import plot_beam_figures
        cuts = beam_cuts(beam_arrays(geometry), medium=medium, frequency_hz=f0)
        paths = plot_beam_figures(cuts, outdir)
        if not as_json:
            for p in paths:
                print(f"wrote {p}")
    return table


def command(args) -> int:
    scene = load(args.scene or default_scene_path())
    beams(scene, Path(args.plots) if args.plots else None, args.json)
    return 0
