"""Atomic outputs: a file or folder appears under its final name complete, or not at all.

Everything abacus writes goes through :func:`staged`: the writer fills a temporary sibling
(``.NAME.tmp-<pid>-<random>``, hidden, in the same folder so the final rename is atomic on one
filesystem), which is renamed over the final name when the writer finishes and removed when it
fails or is interrupted. Temporaries left by a process that was killed (SIGKILL, power loss) are
recognised by their process id and removed by the next write to the same name; the temporaries
of the running process are listed in :data:`ACTIVE` so an interrupt handler can remove them.
"""
from __future__ import annotations

import os
import re
import shutil
import uuid
from contextlib import contextmanager
from pathlib import Path

__all__ = ["staged", "scratch", "write_bytes_atomic", "write_text_atomic", "remove_path",
           "remove_stale", "remove_active", "TMP_MARK", "ACTIVE"]

#: marks the temporaries of :func:`staged` (``.NAME.tmp-<pid>-<random>``)
TMP_MARK = ".tmp-"
#: temporaries this process is writing now
ACTIVE: set = set()
_STALE = re.compile(r"^\..+\.(?:tmp|old)-(\d+)-[0-9a-f]{8}")


def remove_path(path: Path) -> None:
    """Remove a file or a folder tree if it exists (never raises for a missing path)."""
    path = Path(path)
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif path.exists() or path.is_symlink():
        try:
            path.unlink()
        except FileNotFoundError:
            pass


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: alive, not ours to touch
        return True
    return True


def remove_stale(folder: Path, name: str | None = None) -> list[Path]:
    """Remove the temporaries of dead processes in ``folder`` (for ``name`` only, if given).

    Returns
    -------
    list of Path
        What was removed.
    """
    removed = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    for p in entries:
        m = _STALE.match(p.name)
        if m and (name is None or p.name.startswith(f".{name}.")) and not _alive(int(m.group(1))):
            original = p.with_name(p.name[1:p.name.rindex(".old-")]) if ".old-" in p.name else None
            if original is not None and not original.exists():
                os.replace(p, original)   # killed mid-swap: the previous output comes back
                continue
            remove_path(p)
            removed.append(p)
    return removed


def remove_active() -> None:
    """Remove every temporary this process is writing (for an interrupt handler)."""
    for p in list(ACTIVE):
        remove_path(p)
        ACTIVE.discard(p)


@contextmanager
def staged(path, *, suffix: str = ""):
    """Yield a temporary path next to ``path``; on success move it over ``path``.

    Parameters
    ----------
    path : str or Path
        Final file or folder. An existing one is replaced only once the new one is complete.
    suffix : str
        Appended to the temporary name (some writers choose their format by suffix, e.g.
        ``.png`` for matplotlib).

    Yields
    ------
    Path
        Where to write. It does not exist yet; the writer may create a file or a folder.
    """
    path = Path(path)
    remove_stale(path.parent, path.name)
    tag = f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp = path.with_name(f".{path.name}{TMP_MARK}{tag}{suffix}")
    ACTIVE.add(tmp)
    try:
        yield tmp
        if tmp.is_dir() and path.exists():
            # a folder cannot be renamed over another: swap, then remove the old one
            old = path.with_name(f".{path.name}.old-{tag}")
            ACTIVE.add(old)
            os.replace(path, old)
            os.replace(tmp, path)
            remove_path(old)
            ACTIVE.discard(old)
        else:
            os.replace(tmp, path)
    except BaseException:
        remove_path(tmp)
        raise
    finally:
        ACTIVE.discard(tmp)


@contextmanager
def scratch(folder, name: str):
    """Yield a new temporary folder ``folder/.NAME.tmp-<pid>-<random>`` for work that will be
    moved into a :func:`staged` output when it is done (e.g. figures drawn before their output
    folder exists); whatever is left of it is removed on exit, and by the next write of the same
    name if this process is killed.

    Parameters
    ----------
    folder : str or Path
        Where the temporary lives: on the filesystem of the output it will be moved into.
    name : str
        Names the temporary (``.NAME.tmp-...``).
    """
    folder = Path(folder)
    remove_stale(folder, name)
    tmp = folder / f".{name}{TMP_MARK}{os.getpid()}-{uuid.uuid4().hex[:8]}"
    ACTIVE.add(tmp)
    try:
        tmp.mkdir()
        yield tmp
    finally:
        remove_path(tmp)
        ACTIVE.discard(tmp)


def write_bytes_atomic(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns ``path``."""
    path = Path(path)
    with staged(path) as tmp:
        tmp.write_bytes(data)
    return path


def write_text_atomic(path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically; returns ``path``."""
    return write_bytes_atomic(path, text.encode("utf-8"))
