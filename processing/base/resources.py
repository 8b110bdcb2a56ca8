"""Resources a command will need, estimated before any is spent, and the limits they must fit.

Every command that allocates or writes in proportion to its inputs (pings × channels × samples,
images, meshes, rays, sweep points) estimates the peak memory and the bytes it will write, and
refuses up front — with the estimate and the key to change — when either exceeds its limit:

``memory``   ``--max-memory GB`` (commands), else ``$ABACUS_MAX_MEMORY_GB``, else half the
             machine's physical memory;
``disk``     the free space of the output's filesystem (always), and ``$ABACUS_MAX_OUTPUT_GB``
             when set.

Estimates are upper bounds by design (a refusal must not be a surprise, an acceptance must not
end in an allocation error half-way); their terms are documented where they are computed. An
estimate names its *drivers* — the keys whose values the memory grows with (a population's
count, a mesh's segments or file, the pings, a motion file's rows) and how much of it each
accounts for — so that a refusal names the key that matters most and what of it fits.
"""
from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["ResourceError", "Estimate", "Driver", "memory_limit_bytes", "check_resources", "fmt_bytes",
           "usable_cores"]

GB = 1024 ** 3


class ResourceError(ValueError):
    """A command that would need more memory or disk than allowed (the message says how much,
    what drives it and which key or option to change)."""


def fmt_bytes(n: float) -> str:
    """Bytes for people: 512 B, 3.4 MB, 2.1 GB."""
    n = float(n)
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(n) >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n:.0f} B"


@dataclass(frozen=True)
class Driver:
    """A key the memory of an estimate grows with, in proportion.

    Attributes
    ----------
    key : str
        The key or option (``"targets.populations[0].count"``, ``"boundaries[1].mesh.segments"``).
    amount : float
        How much of it the estimate counts (targets, faces, pings, rows).
    unit : str
        What ``amount`` counts ("targets", "faces").
    bytes : float
        The memory it accounts for (in proportion to ``amount``).
    """

    key: str
    amount: float
    unit: str
    bytes: float

    def fitting(self, memory_bytes: float, limit_bytes: float) -> float:
        """How much of it fits ``limit_bytes`` when the rest of ``memory_bytes`` stays."""
        rest = memory_bytes - self.bytes
        if self.bytes <= 0 or not math.isfinite(self.bytes) or rest >= limit_bytes:
            return 0.0
        return self.amount * (limit_bytes - rest) / self.bytes


def _amount(x: float) -> str:
    return f"{x:,.0f}" if x < 1e9 else f"{x:.3g}"


@dataclass
class Estimate:
    """What a command will need.

    Attributes
    ----------
    memory_bytes : float
        Peak memory above the interpreter's own.
    output_bytes : float
        Bytes written.
    terms : list of (str, float)
        What makes up the memory (for the message), largest first.
    keys : str
        The scene keys or options that drive it (for the message).
    drivers : list of Driver
        The keys it grows with and their shares, for the message of a refusal.
    """

    memory_bytes: float = 0.0
    output_bytes: float = 0.0
    terms: list = field(default_factory=list)
    keys: str = ""
    drivers: list = field(default_factory=list)

    def largest_driver(self):
        """The :class:`Driver` that accounts for the most memory (the first listed of those
        within 1 % of it: the pings before the samples they hold), or None."""
        drivers = [d for d in self.drivers if d.bytes > 0]
        if not drivers:
            return None
        top = max(d.bytes for d in drivers)
        return next(d for d in drivers if d.bytes >= 0.99 * top)

    def what_fits(self, limit_bytes: float) -> str:
        """For a refusal: the key that drives most of the memory and how much of it fits
        ``limit_bytes`` (the rest unchanged), and what to reduce."""
        d = self.largest_driver()
        if d is None:
            return f"reduce {self.keys or 'the input'}"
        fit = d.fitting(self.memory_bytes, limit_bytes)
        head = f"most of it is {d.key} ({_amount(d.amount)} {d.unit}, {fmt_bytes(d.bytes)})"
        if fit >= 1:
            return f"{head}: about {_amount(math.floor(fit))} {d.unit} fit; reduce it"
        return (f"{head}, and without it the rest still exceeds the limit; reduce "
                f"{self.keys or 'the input'}")

    def describe(self) -> str:
        parts = ", ".join(f"{name} {fmt_bytes(b)}" for name, b in
                          sorted(self.terms, key=lambda t: -t[1])[:4])
        return (f"≈ {fmt_bytes(self.memory_bytes)} of memory ({parts}) and "
                f"{fmt_bytes(self.output_bytes)} written")


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _physical_memory() -> float:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 8.0 * GB


def memory_limit_bytes(max_memory_gb: float | None = None) -> float:
    """The memory a command may use: the option, else ``$ABACUS_MAX_MEMORY_GB``, else half the
    physical memory.

    Raises
    ------
    ResourceError
        A limit that is not a positive number.
    """
    value = max_memory_gb
    source = "--max-memory"
    if value is None and os.environ.get("ABACUS_MAX_MEMORY_GB"):
        value, source = os.environ["ABACUS_MAX_MEMORY_GB"], "ABACUS_MAX_MEMORY_GB"
    if value is None:
        return _physical_memory() / 2
    try:
        gb = float(value)
    except ValueError:
        raise ResourceError(f"{source}={value!r}: give the limit in GB, a positive number") from None
    if not (gb > 0 and gb < 1e6):
        raise ResourceError(f"{source}={value!r}: give the limit in GB, a positive number")
    return gb * GB


def check_resources(estimate: Estimate, *, what: str, output: Path | None = None,
                    max_memory_gb: float | None = None) -> None:
    """Refuse a command whose estimate exceeds the memory limit or the output's free space.

    Raises
    ------
    ResourceError
    """
    limit = memory_limit_bytes(max_memory_gb)
    if estimate.memory_bytes > limit:
        raise ResourceError(
            f"{what} would need {estimate.describe()}, over the memory limit of {fmt_bytes(limit)}: "
            f"{estimate.what_fits(limit)}, or raise the limit (--max-memory GB or "
            f"ABACUS_MAX_MEMORY_GB)")
    if output is not None and estimate.output_bytes > 0:
        folder = Path(output).parent
        try:
            free = shutil.disk_usage(folder if folder.exists() else Path.cwd()).free
        except OSError:
            free = None
        if free is not None and estimate.output_bytes > free:
            raise ResourceError(f"{what} would write ≈ {fmt_bytes(estimate.output_bytes)} but "
                                f"{folder} has {fmt_bytes(free)} free: reduce {estimate.keys or 'the input'}, "
                                f"or write elsewhere (-o)")
        cap = os.environ.get("ABACUS_MAX_OUTPUT_GB")
        if cap:
            try:
                cap_b = float(cap) * GB
            except ValueError:
                raise ResourceError(f"ABACUS_MAX_OUTPUT_GB={cap!r}: give the limit in GB") from None
            if estimate.output_bytes > cap_b:
                raise ResourceError(f"{what} would write ≈ {fmt_bytes(estimate.output_bytes)}, over "
                                    f"ABACUS_MAX_OUTPUT_GB = {cap} GB: reduce {estimate.keys or 'the input'}")
