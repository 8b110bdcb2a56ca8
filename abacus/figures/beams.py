"""Beam-pattern figures like the thesis' Figures 3.11, 3.15 and 3.17 (matplotlib, Agg)."""
from __future__ import annotations

from pathlib import Path

from processing.base.atomic import staged
from abacus.figures.plots import fixed_layout

__all__ = ["plot_beam_figures", "BEAM_FIGURES", "BEAM_FIGURE_STYLE"]

#: the files :func:`plot_beam_figures` writes, in order
BEAM_FIGURES = ("beams_transmitter.png", "beams_receiver.png", "beams_receiver_modes.png")
#: the drawing's edition, part of the geometry cache's key for these figures: a change of how they
#: are drawn must not be served from PNGs cached by the previous drawing
BEAM_FIGURE_STYLE = 2


def _figure(cuts, keys, labels, title, path, *, spans=None):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    fixed_layout(fig, top=0.75, bottom=1.0, wspace=0.22)
    for ax, plane in zip(axes, ("azimuth", "elevation")):
        for key, label, style in zip(keys, labels, ("-", "--", ":")):
            deg, db = cuts[key][plane]
            ax.plot(deg, db, style, lw=1.3, label=label)
        if spans and plane in spans:
            ax.set_xlim(-spans[plane], spans[plane])
        ax.set_ylim(-60, 3)
        ax.axhline(-3, color="0.6", lw=0.6)
        ax.set_xlabel(f"{'azimuth θ' if plane == 'azimuth' else 'elevation φ'} (deg)")
        ax.set_ylabel("directivity 20 log₁₀ |E| / max |E| (dB)")
        ax.set_title(f"{plane} cut ({'φ' if plane == 'azimuth' else 'θ'} = 0); grey: −3 dB")
        ax.grid(alpha=0.3)
    # one legend below both cuts: inside, it hid the sidelobes it names
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=len(keys), fontsize=9)
    fig.suptitle(title)
    with staged(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def plot_beam_figures(cuts: dict, outdir: str | Path) -> list[Path]:
    """Write beams_transmitter.png (Fig. 3.11), beams_receiver.png (Fig. 3.15) and
    beams_receiver_modes.png (Fig. 3.17) into ``outdir``; return their paths."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    paths = [outdir / name for name in BEAM_FIGURES]
    _figure(cuts, [("transmitter", "generic", "normal"), ("transmitter", "abacus", "normal")],
            ["generic transmitter", "ABACUS transmitter"],
            "Transmitter directivity, generic vs ABACUS (thesis Fig. 3.11)", paths[0],
            spans={"azimuth": 30, "elevation": 6})
    _figure(cuts, [("receiver", "generic", "normal"), ("receiver", "abacus", "normal")],
            ["generic receiver (16 el.)", "ABACUS receiver (16 el.)"],
            "Receiver subarray directivity, generic vs ABACUS (thesis Fig. 3.15)", paths[1],
            spans={"azimuth": 30, "elevation": 30})
    _figure(cuts, [("receiver", "abacus", "normal"), ("receiver", "abacus", "interferometric")],
            ["normal mode (16 el.)", "interferometric mode (8 el.)"],
            "ABACUS receiver, normal vs interferometric mode (thesis Fig. 3.17)", paths[2],
            spans={"azimuth": 30, "elevation": 30})
    return paths
