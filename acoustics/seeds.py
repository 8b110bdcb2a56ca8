"""Seeding: every random draw of a simulation comes from (scene seed, ping, stream, group).

``default_rng(SeedSequence([seed, ping, stream, group]))`` makes a ping depend only on the scene
seed and that ping's index, whatever the order pings run in or the number of workers; a named
stream per purpose means adding a new kind of draw never shifts an existing one.
"""
from __future__ import annotations

import numpy as np

__all__ = ["FIXED", "STREAMS", "SEED_MAX", "ping_rng", "stream_seed"]

#: the largest scene seed: seeds are stored as signed 64-bit integers in every dataset
SEED_MAX = 2**63 - 1

#: stands for the ping index in the seed of draws that do not change between pings
FIXED = 2**31 - 1
#: purpose of each random stream (part of the seed, so adding a stream never shifts another)
STREAMS = {"positions": 1, "count": 2, "backscatter": 3, "phase": 4, "noise": 5, "reverberation": 6,
           "motion": 7, "turns": 8, "tilt": 9}


def stream_seed(seed: int, ping: int, stream: str, group: int = 0) -> np.random.SeedSequence:
    """The seed of one purpose of one ping (a fresh generator from it restarts the stream)."""
    return np.random.SeedSequence([int(seed), int(ping), STREAMS[stream], int(group)])


def ping_rng(seed: int, ping: int, stream: str, group: int = 0) -> np.random.Generator:
    """The generator for one purpose of one ping (see module docstring)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(ping), STREAMS[stream],
                                                         int(group)]))
