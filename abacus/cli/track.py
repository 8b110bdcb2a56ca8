"""``abacus track``: track the fish of a dataset across pings, count each passage once."""
from __future__ import annotations

from abacus.cli.common import add_output_options, check_outputs, save_tree

HELP = "track detections across pings: per-fish tracks, TS, speed and track-based counts"


def add_parser(sub):
    c = sub.add_parser("track", help=HELP)
    c.add_argument("input", help="dataset (.nc or .zarr); detected and counted first if needed")
    c.add_argument("-o", "--output", help="output dataset with /Processing/Tracks")
    c.add_argument("--settings", metavar="YAML", help="processing settings (default: the scene's)")
    c.add_argument("--json", action="store_true", help="print one JSON object: per-track rows and summary")
    c.add_argument("--csv", metavar="FILE", help="write one row per track as CSV")
    c.add_argument("--plots", metavar="DIR", help="tracks in 3-D and from above and the side; TS along tracks")
    c.add_argument("--mot", metavar="DIR",
                   help="write the tracks (DIR/tracks.txt) and the truth (DIR/gt.txt) as MOTChallenge 3-D "
                        "text files: frame,id,-1,-1,-1,-1,conf,x,y,z (docs/validation.md)")
    add_output_options(c)
    c.set_defaults(func=command)


def _check_ping_times(tree, source: str) -> None:
    """Refuse a dataset whose ping times are missing or do not increase: tracks need the time
    between pings (one line naming the file and the first ping out of order)."""
    import numpy as np

    from processing.base.dataset import ELEMENT_GROUP, DatasetError, group_of
    eg = group_of(tree, ELEMENT_GROUP)
    if eg is None or "ping_time" not in eg.variables:
        return                                   # the reader names what is missing
    t = eg["ping_time"].values
    if np.issubdtype(t.dtype, np.datetime64):
        bad = np.isnat(t)
    elif t.dtype.kind in "iuf":
        bad = ~np.isfinite(t.astype(float))
    else:
        raise DatasetError(f"{source}: /{ELEMENT_GROUP}/ping_time holds {t.dtype} values; tracking needs "
                           f"the time of every ping")
    if bad.any():
        raise DatasetError(f"{source}: /{ELEMENT_GROUP}/ping_time of ping {int(np.flatnonzero(bad)[0])} is "
                           f"missing (NaT/NaN); tracking needs the time of every ping")
    step = np.diff(t)
    back = np.flatnonzero(~(step > np.zeros_like(step)))
    if back.size:
        i = int(back[0]) + 1
        raise DatasetError(f"{source}: /{ELEMENT_GROUP}/ping_time does not increase: ping {i} ({t[i]}) does "
                           f"not come after ping {i - 1} ({t[i - 1]}); tracking needs pings in time order")


def write_mot_files(tree, folder) -> list:
    """Write the tracks and the truth of a tracked dataset as MOTChallenge 3-D text files.

    ``folder/tracks.txt``: one line per track point, ``folder/gt.txt`` (when the dataset has
    ground truth): one line per true fish per ping of the record; each line
    ``frame,id,-1,-1,-1,-1,conf,x,y,z`` with frame = ping index + 1, id = track number + 1 or
    ``target_id`` + 1, conf = 1 inside the counting volume the tracks were counted in (at each
    ping's pose) and 0 outside, x, y, z the world position (m)
    (:func:`processing.tracking.hota.write_mot`).

    Returns
    -------
    list of Path
        The files written.
    """
    from pathlib import Path

    import numpy as np

    from processing.base.contract import ELEMENT_GROUP, TRUTH_GROUP
    from processing.base.dataset import group_of, ping_indices
    from processing.tracking.hota import write_mot
    from processing.tracking.tracks import tracks_of, truth_in_volume
    folder = Path(folder)
    ds = tracks_of(tree)
    written = [write_mot(folder / "tracks.txt", ds["point_ping_index"].values.astype(int) + 1,
                         ds["point_track"].values.astype(int) + 1,
                         np.stack([ds[f"point_world_{a}"].values for a in "xyz"], -1),
                         ds["point_in_volume"].values.astype(int))]
    gt = group_of(tree, TRUTH_GROUP)
    if gt is not None and "target_id" in gt:
        pings = gt["target_ping_index"].values.astype(int)
        keep = np.isin(pings, ping_indices(tree[ELEMENT_GROUP].ds))
        # the volume the tracks were counted and scored in (count.range_m included)
        conf = truth_in_volume(tree).astype(int)
        written.append(write_mot(folder / "gt.txt", pings[keep] + 1, gt["target_id"].values.astype(int)[keep] + 1,
                                 np.stack([gt[f"target_world_{a}"].values for a in "xyz"], -1)[keep],
                                 conf[keep]))
    return written


def command(args) -> int:
    import processing
    from processing.base.atomic import staged_set
    from processing.base.dataset import open_tree
    from processing.tracking.tracks import format_tracks, track_summary, write_tracks_csv, strict_json
    out, csv, plots, mot = check_outputs(
        args, [("-o", args.output, False), ("--csv", args.csv, False), ("--plots", args.plots, True),
               ("--mot", args.mot, True)],
        inputs=[args.input, args.settings])
    tree = open_tree(args.input, max_memory_gb=args.max_memory, work_factor=3.0)
    _check_ping_times(tree, str(args.input))
    from processing.base.contract import COUNTS_GROUP
    from processing.base.dataset import has_group
    if not has_group(tree, COUNTS_GROUP):
        tree = processing.count(tree, args.settings)
    tree = processing.track(tree, args.settings)
    result = track_summary(tree)
    # every output to a temporary, all renamed into place at the end: an error, a full disk
    # or an interrupt part-way leaves none of them
    with staged_set() as outputs:
        if out is not None:
            save_tree(tree, outputs.path(out), final=out)
        if csv is not None:
            write_tracks_csv(tree, outputs.path(csv))
        if plots is not None:
            from abacus.figures.tracks import track_figures
            tmp = outputs.path(plots)
            tmp.mkdir()
            track_figures(tree, tmp)
        if mot is not None:
            tmp = outputs.path(mot)
            tmp.mkdir()
            write_mot_files(tree, tmp)
    if args.json:
        print(strict_json(result))
    else:
        print(format_tracks(result))
        for what, where in (("dataset", args.output), ("tracks CSV", args.csv), ("plots", args.plots),
                            ("MOTChallenge files", args.mot)):
            if where:
                print(f"wrote {what}: {where}")
    return 0
