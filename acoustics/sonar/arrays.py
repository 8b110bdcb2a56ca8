"""Arrays of rectangular piston elements: the transmitter and the receiver subarrays.

An element is a flat rectangular piston in the sonar frame's x–y plane facing +z, with a
centre, a width along its local x, a height along its local y, an in-plane rotation
(local x turned from +x towards +y) and an amplitude weight. Arrays are structures of
arrays (one row per element), read-only, in the style of trimesh's ray results.

The ABACUS presets (thesis §3.1, Tables 3.2–3.3, ../shared/reference/ABACUS.md) are built by
:func:`abacus_transmitter` and :func:`abacus_receiver`; the choices the thesis leaves open
are documented in docs/arrays.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from acoustics.sonar import preset

__all__ = ["ElementArray", "Receiver", "abacus_transmitter", "abacus_receiver", "MODES",
           "mode_channels"]

MODES = ("interferometric", "normal", "combined")


def _readonly(a, dtype=float):
    a = np.array(a, dtype=dtype)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class ElementArray:
    """Rectangular piston elements, one row per element.

    Attributes
    ----------
    center_m : ndarray, shape (n, 3)
        Element centres (m) in the sonar frame; elements face +z.
    width_m : ndarray, shape (n,)
        Size (m) along the element's local x.
    height_m : ndarray, shape (n,)
        Size (m) along the element's local y.
    rotation_rad : ndarray, shape (n,)
        In-plane rotation (rad) of local x from +x towards +y.
    weight : ndarray, shape (n,)
        Amplitude weight (dimensionless); a ganged transmitter has all weights 1.
    name : str
        Label used in plots and datasets.
    """

    center_m: np.ndarray
    width_m: np.ndarray
    height_m: np.ndarray
    rotation_rad: np.ndarray
    weight: np.ndarray
    name: str = "array"

    def __post_init__(self):
        c = _readonly(self.center_m).reshape(-1, 3)
        n = c.shape[0]
        if n == 0:
            raise ValueError(f"{self.name}: an array needs at least one element")
        cols = {}
        for key in ("width_m", "height_m", "rotation_rad", "weight"):
            v = np.broadcast_to(np.asarray(getattr(self, key), float), (n,))
            cols[key] = _readonly(v)
        if not (np.all(np.isfinite(c)) and all(np.all(np.isfinite(v)) for v in cols.values())):
            raise ValueError(f"{self.name}: element geometry must be finite")
        if np.any(cols["width_m"] <= 0) or np.any(cols["height_m"] <= 0):
            raise ValueError(f"{self.name}: element widths and heights must be > 0")
        object.__setattr__(self, "center_m", c)
        for key, v in cols.items():
            object.__setattr__(self, key, v)

    @property
    def n_elements(self) -> int:
        return self.center_m.shape[0]

    def __len__(self) -> int:
        return self.n_elements

    @property
    def phase_center_m(self) -> np.ndarray:
        """Weighted centroid (m), shape (3,): where processing references phase."""
        w = np.abs(self.weight)
        return (self.center_m * w[:, None]).sum(0) / w.sum()

    @property
    def local_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit vectors of each element's local x and y in the sonar frame, shapes (n, 3)."""
        c, s = np.cos(self.rotation_rad), np.sin(self.rotation_rad)
        z = np.zeros_like(c)
        return np.stack([c, s, z], -1), np.stack([-s, c, z], -1)

    @property
    def extent_m(self) -> np.ndarray:
        """Bounding size (m) of the element centres along x, y, z, shape (3,)."""
        return self.center_m.max(0) - self.center_m.min(0)

    def subset(self, index, name: str | None = None) -> "ElementArray":
        """Elements ``index`` (array of ints) as a new array."""
        idx = np.asarray(index, int)
        return ElementArray(self.center_m[idx], self.width_m[idx], self.height_m[idx],
                            self.rotation_rad[idx], self.weight[idx], name or self.name)

    def translated(self, offset_m) -> "ElementArray":
        return ElementArray(self.center_m + np.asarray(offset_m, float), self.width_m,
                            self.height_m, self.rotation_rad, self.weight, self.name)

    @classmethod
    def concatenate(cls, arrays, name: str) -> "ElementArray":
        return cls(np.concatenate([a.center_m for a in arrays]),
                   np.concatenate([a.width_m for a in arrays]),
                   np.concatenate([a.height_m for a in arrays]),
                   np.concatenate([a.rotation_rad for a in arrays]),
                   np.concatenate([a.weight for a in arrays]), name)


@dataclass(frozen=True, eq=False)
class Receiver:
    """The receiving side: physical subarrays and the channels actually recorded.

    Attributes
    ----------
    subarrays : dict[str, ElementArray]
        The physical subarrays ("A", "B"), every element.
    channels : tuple[tuple[str, int], ...]
        Recorded channels in order: (subarray name, element index within it).
    mode : str
        "interferometric" (images from A and B separately), "normal" (one subarray)
        or "combined" (all channels form one image).
    """

    subarrays: dict
    channels: tuple
    mode: str
    _elements: ElementArray = field(init=False, repr=False)

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}")
        if not self.channels:
            raise ValueError("a receiver needs at least one recorded channel")
        parts = []
        for sub, idx in self.channels:
            parts.append(self.subarrays[sub].subset([idx]))
        object.__setattr__(self, "_elements", ElementArray.concatenate(parts, "receiver"))

    @property
    def elements(self) -> ElementArray:
        """The recorded channels as one array, in channel order."""
        return self._elements

    @property
    def channel_subarray(self) -> np.ndarray:
        """Subarray name of each recorded channel, shape (n_channels,)."""
        return np.array([s for s, _ in self.channels])

    @property
    def image_groups(self) -> dict:
        """Channels (indices into :attr:`elements`) that form each image."""
        names = self.channel_subarray
        if self.mode == "combined":
            return {"AB": np.arange(len(names))}
        return {s: np.flatnonzero(names == s) for s in dict.fromkeys(names)}


def abacus_transmitter(variant: str = "abacus", *, stagger_m: float | None = None,
                       rotated_end_elements: int | None = None) -> ElementArray:
    """The ABACUS transmitter: 16 ganged elements stacked along y.

    Parameters
    ----------
    variant : {"generic", "abacus"}
        "generic": a straight line of 0.020 x 0.012 m elements, pitch 0.012 m (length
        0.192 m). "abacus": elements shifted alternately ±stagger along x and the three
        end elements on each side rotated 90° (0.012 x 0.020 m), stacked edge to edge
        (length 0.240 m).
    stagger_m : float, optional
        Overrides the variant's stagger (generic 0, abacus :data:`acoustics.sonar.preset.TX_STAGGER_M`).
    rotated_end_elements : int, optional
        Overrides the number of rotated elements at each end (generic 0, abacus 3).

    Returns
    -------
    ElementArray
        16 elements centred on the sonar-frame origin.
    """
    if variant not in ("generic", "abacus"):
        raise ValueError("variant must be 'generic' or 'abacus'")
    n = preset.ELEMENTS_PER_ARRAY
    stagger = (preset.TX_STAGGER_M if variant == "abacus" else 0.0) if stagger_m is None else stagger_m
    n_rot = (3 if variant == "abacus" else 0) if rotated_end_elements is None else rotated_end_elements
    w, h = preset.TX_ELEMENT_M
    rotated = np.zeros(n, bool)
    if n_rot:
        rotated[:n_rot] = True
        rotated[n - n_rot:] = True
    extent_y = np.where(rotated, w, h)  # a rotated element is w tall
    y_edges = np.concatenate([[0.0], np.cumsum(extent_y)])
    y = 0.5 * (y_edges[:-1] + y_edges[1:]) - y_edges[-1] / 2
    x = stagger * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    centers = np.column_stack([x, y, np.zeros(n)])
    return ElementArray(centers, np.full(n, w), np.full(n, h),
                        np.where(rotated, np.pi / 2, 0.0), np.ones(n), "transmitter")


def abacus_receiver(variant: str = "abacus", *, stagger_m: float | None = None,
                    b_offset_m: float | None = None,
                    baseline_m: float = preset.BASELINE_M) -> dict:
    """The two ABACUS receiver subarrays A and B, 16 elements each along x.

    Subarray A lies at y = -b/2 and B at y = +b/2, so that the interferometric phase
    ψ_AB = ψ_A - ψ_B = -(2π/λ) b sin φ as the thesis writes it (eq. 4.58).

    Parameters
    ----------
    variant : {"generic", "abacus"}
        "abacus" shifts elements alternately ±stagger along y and shifts B along x by
        half a pitch; "generic" does neither.
    stagger_m, b_offset_m : float, optional
        Override the variant's vertical stagger and B's x shift (m).
    baseline_m : float
        Separation of the subarrays' rows along y (m).

    Returns
    -------
    dict[str, ElementArray]
        ``{"A": ..., "B": ...}``.
    """
    if variant not in ("generic", "abacus"):
        raise ValueError("variant must be 'generic' or 'abacus'")
    n = preset.ELEMENTS_PER_ARRAY
    stagger = (preset.RX_STAGGER_M if variant == "abacus" else 0.0) if stagger_m is None else stagger_m
    b_off = (preset.SUBARRAY_B_OFFSET_M if variant == "abacus" else 0.0) if b_offset_m is None else b_offset_m
    w, h = preset.RX_ELEMENT_M
    x = (np.arange(n) - (n - 1) / 2) * preset.RX_PITCH_M
    dy = stagger * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    out = {}
    for name, y0, x0 in (("A", -baseline_m / 2, -b_off / 2), ("B", baseline_m / 2, b_off / 2)):
        centers = np.column_stack([x + x0, y0 + dy, np.zeros(n)])
        out[name] = ElementArray(centers, np.full(n, w), np.full(n, h), np.zeros(n),
                                 np.ones(n), f"subarray {name}")
    return out


def mode_channels(mode: str, n_per_subarray: int = 16) -> tuple:
    """The recorded channels of the ABACUS data capture system (16 channels, §3.4.1).

    interferometric and combined: the middle 8 elements of A and of B; normal: all 16
    elements of A.
    """
    mid = range((n_per_subarray - 8) // 2, (n_per_subarray - 8) // 2 + 8)
    if mode == "normal":
        return tuple(("A", i) for i in range(n_per_subarray))
    if mode in ("interferometric", "combined"):
        return tuple(("A", i) for i in mid) + tuple(("B", i) for i in mid)
    raise ValueError(f"mode must be one of {MODES}")
