"""Which stages of a run ran, and how long each took (recorded in every dataset's provenance)."""
from __future__ import annotations

import time
from contextlib import contextmanager

__all__ = ["StageLog"]


class StageLog:
    """Accumulates wall time per named stage, in the order stages first ran.

    A stage that the scene does not need is never entered, so it never appears: the log is
    the record of what the run actually did.
    """

    def __init__(self):
        self._seconds: dict[str, float] = {}
        self._calls: dict[str, int] = {}

    @contextmanager
    def stage(self, name: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self._seconds[name] = self._seconds.get(name, 0.0) + time.perf_counter() - t0
            self._calls[name] = self._calls.get(name, 0) + 1

    def add(self, name: str, seconds: float, calls: int = 1):
        self._seconds[name] = self._seconds.get(name, 0.0) + seconds
        self._calls[name] = self._calls.get(name, 0) + calls

    @property
    def names(self) -> list[str]:
        return list(self._seconds)

    @property
    def seconds(self) -> dict[str, float]:
        return dict(self._seconds)

    @property
    def calls(self) -> dict[str, int]:
        return dict(self._calls)

    def merge(self, other: "StageLog"):
        for name, s in other._seconds.items():
            self.add(name, s, other._calls[name])

    def __contains__(self, name: str) -> bool:
        return name in self._seconds

    def summary(self) -> str:
        return ", ".join(f"{k} {v:.3f} s" for k, v in self._seconds.items())
