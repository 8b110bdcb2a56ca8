"""``abacus run``: the main job — simulate, image, detect, locate, count; dataset and plots."""
from __future__ import annotations

import json
from pathlib import Path

from acoustics.cli.common import Progress, load, ping_list

HELP = "the main job: simulate, image, detect, locate, count"


def add_parser(sub):
    r = sub.add_parser("run", help=HELP)
    r.add_argument("scene", help="scene file (YAML) or a built-in scene's name (e.g. default)")
    r.add_argument("-o", "--output", help="output folder (default runs/<scene name>)")
    r.add_argument("--pings", type=int, help="number of pings (default: the scene's)")
    r.set_defaults(func=command)


def command(args) -> int:
    import processing
    from acoustics.cli.beams import beams
    from acoustics.simulation.run import simulate
    from processing.dataset import write_tree
    scene = load(args.scene)
    outdir = Path(args.output or Path("runs") / scene.name)
    outdir.mkdir(parents=True, exist_ok=True)
    print(f"scene '{scene.name}' ({args.scene}): {scene.pings.count} ping(s), "
          f"sha256 {scene.sha256()[:12]}")
    (outdir / "scene.resolved.yaml").write_text(scene.resolved_text())
    beams(scene, outdir / "beams", False)
    tree = simulate(scene, pings=ping_list(scene, args.pings), progress=Progress("simulate"))
    tree = processing.count(tree)
    result = processing.count_summary(tree)
    write_tree(tree, outdir / "run.nc")
    processing.write_csv(tree, outdir / "detections.csv")
    (outdir / "counts.json").write_text(json.dumps(result, indent=1))
    from processing.plots import count_figures, image_figures
    image_figures(processing.images_of(tree), outdir / "images")
    n = tree["Processing/Counts"].sizes["ping_time"]
    count_figures(tree, outdir / "counts", pings=range(min(n, 3)))
    print()
    print(processing.format_counts(result))
    print(f"\noutputs in {outdir}/: run.nc (dataset), detections.csv, counts.json, beams/, images/, counts/")
    return 0
