"""The sonar as the simulator uses it: transmitter, receiver channels, pose, built from a scene."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acoustics.sonar.arrays import ElementArray, Receiver, abacus_receiver, abacus_transmitter, mode_channels
from acoustics.frames import Pose

__all__ = ["Sonar", "build_sonar", "preset_sonar"]


@dataclass(frozen=True, eq=False)
class Sonar:
    """Transmitter, receiver and pose.

    Attributes
    ----------
    transmitter : ElementArray
        Ganged transmit elements (one channel).
    receiver : Receiver
        Physical subarrays and recorded channels.
    pose : Pose
        Sonar frame in the world frame.
    """

    transmitter: ElementArray
    receiver: Receiver
    pose: Pose

    @property
    def n_channels(self) -> int:
        return self.receiver.elements.n_elements


def preset_sonar(*, tx_variant: str = "abacus", rx_variant: str = "abacus",
                 mode: str = "interferometric", pose: Pose | None = None, geometry: dict | None = None) -> Sonar:
    """The ABACUS preset. ``geometry`` overrides keys of ``PresetGeometry`` (m)."""
    g = dict(geometry or {})
    tx = abacus_transmitter(tx_variant, stagger_m=g.get("transmitter_stagger_m"),
                            rotated_end_elements=g.get("transmitter_rotated_end_elements"))
    subs = abacus_receiver(rx_variant, stagger_m=g.get("receiver_stagger_m"),
                           b_offset_m=g.get("subarray_b_offset_m"),
                           **({"baseline_m": g["baseline_m"]} if "baseline_m" in g else {}))
    rx = Receiver(subs, mode_channels(mode), mode)
    return Sonar(tx, rx, pose or Pose(np.zeros(3), np.eye(3)))


def build_sonar(scene) -> Sonar:
    """Build the runtime :class:`Sonar` of a validated scene."""
    spec = scene.sonar
    pose = Pose.from_axes(spec.pose.position_m, spec.pose.boresight, spec.pose.receiver_axis)
    if spec.preset == "abacus":
        return preset_sonar(tx_variant=spec.variant, rx_variant=spec.variant, mode=spec.mode,
                            pose=pose, geometry=spec.preset_geometry.model_dump())
    tx = spec.transmitter.build("transmitter")
    subs = {"A": spec.receiver.A.build("subarray A")}
    if spec.receiver.B is not None:
        subs["B"] = spec.receiver.B.build("subarray B")
    channels = []
    names = ("A", "B") if spec.mode != "normal" else ("A",)
    for name in names:
        if name not in subs:
            continue
        chosen = getattr(spec.receiver, f"channels_{name}")
        n = subs[name].n_elements
        idx = range(n) if chosen is None else chosen
        channels.extend((name, int(i)) for i in idx)
    return Sonar(tx, Receiver(subs, tuple(channels), spec.mode), pose)
