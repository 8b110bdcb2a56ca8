"""The label cube of an image beside the image (matplotlib, Agg; imported lazily by the CLI)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from abacus.figures.plots import fixed_layout, save

__all__ = ["draw_label_figure", "CLASS_COLOURS"]

#: class code -> (name, colour)
CLASS_COLOURS = {0: ("noise", "#f2f2f2"), 1: ("target", "#1b7837"), 2: ("surface", "#2166ac"),
                 3: ("floor", "#8c510a"), 4: ("multipath ghost", "#d6604d"),
                 5: ("grating-lobe ghost", "#762a83"), 6: ("obstacle", "#878787")}


def draw_label_figure(image, label_class, label_id, label_fraction, range_m, beam_angle_rad,
                      path: Path, *, title: str = "", dynamic_range_db: float = 60.0,
                      annotate_db: float = -50.0) -> Path:
    """labels.png: |I(r, θ)| (dB) and the class of each cell's dominant contributor, the
    brightest cells of each class and target annotated with their id.

    Parameters
    ----------
    image : ndarray, shape (n_range, n_beams), complex
    label_class, label_id : ndarray of int, shape (n_range, n_beams)
    label_fraction : ndarray, shape (n_range, n_beams)
    range_m : ndarray, shape (n_range,)
    beam_angle_rad : ndarray, shape (n_beams,)
    path : Path
    dynamic_range_db : float
        Shown below the image's peak.
    annotate_db : float
        Cells this far below the peak and brighter may be annotated.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm, ListedColormap

    mag = np.abs(image)
    db = 20 * np.log10(np.maximum(mag, 1e-300) / max(float(mag.max()), 1e-300))
    th = np.degrees(beam_angle_rad)
    extent = [th[0], th[-1], range_m[0], range_m[-1]]
    fig, axes = plt.subplots(1, 2, figsize=(12, 6))
    fixed_layout(fig, left=0.7, right=1.9, wspace=0.35)
    m = axes[0].imshow(db, origin="lower", aspect="auto", extent=extent, vmin=-dynamic_range_db,
                       vmax=0, cmap="viridis", interpolation="nearest")
    fig.colorbar(m, ax=axes[0]).set_label("|I| (dB re max)")
    axes[0].set_title("image, subarray A" + (f" — {title}" if title else ""))
    codes = sorted(CLASS_COLOURS)
    cmap = ListedColormap([CLASS_COLOURS[c][1] for c in codes])
    norm = BoundaryNorm(np.arange(len(codes) + 1) - 0.5, len(codes))
    axes[1].imshow(label_class, origin="lower", aspect="auto", extent=extent, cmap=cmap, norm=norm,
                   interpolation="nearest")
    handles = [matplotlib.patches.Patch(color=CLASS_COLOURS[c][1], label=CLASS_COLOURS[c][0])
               for c in codes if (label_class == c).any()]
    axes[1].legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=9)
    axes[1].set_title("dominant contributor's class (id of its target)")
    # each (class, id) annotated once, at its brightest cell
    for c in codes:
        if c == 0:
            continue
        for tid in np.unique(label_id[label_class == c]):
            sel = (label_class == c) & (label_id == tid) & (db >= annotate_db)
            if not sel.any():
                continue
            r, b = np.unravel_index(np.argmax(np.where(sel, db, -np.inf)), db.shape)
            text = f"{CLASS_COLOURS[c][0]} {tid}" if tid >= 0 else CLASS_COLOURS[c][0]
            right = th[b] > 0.5 * (th[0] + th[-1])      # text towards the image's centre
            for ax in axes:
                ax.annotate(text + f" ({db[r, b]:.0f} dB)" if ax is axes[0] else text,
                            (th[b], range_m[r]), xytext=(-6 if right else 6, 4),
                            textcoords="offset points", ha="right" if right else "left",
                            fontsize=8, color="white" if ax is axes[0] else "black")
                ax.plot(th[b], range_m[r], "+", color="white" if ax is axes[0] else "black", ms=8)
    for ax in axes:
        ax.set_xlabel("beam azimuth θ (deg)")
        ax.set_ylabel("range r (m)")
        ax.invert_yaxis()           # range grows downward, as on an echogram (the run's figures)
    out = save(fig, Path(path))
    plt.close(fig)
    return out
