"""Atomic outputs: a file or folder appears under its final name complete, or not at all.

Everything abacus writes goes through :func:`staged`: the writer fills a temporary sibling
(``.NAME.tmp-XXXXXXXX``, hidden, in the same folder so the final rename is atomic on one
filesystem), which is renamed over the final name when the writer finishes and removed when it
fails or is interrupted.
"""
from __future__ import annotations

import os
import shutil
import uuid
from contextlib import contextmanager
from pathlib import Path

__all__ = ["staged", "write_bytes_atomic", "write_text_atomic", "remove_path", "TMP_MARK"]

#: marks the temporaries of :func:`staged` (``.NAME.tmp-XXXXXXXX``)
TMP_MARK = ".tmp-"


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
    tmp = path.with_name(f".{path.name}{TMP_MARK}{uuid.uuid4().hex[:8]}{suffix}")
    try:
        yield tmp
        if tmp.is_dir() and path.exists():
            # a folder cannot be renamed over another: swap, then remove the old one
            old = path.with_name(f".{path.name}.old-{uuid.uuid4().hex[:8]}")
            os.replace(path, old)
            os.replace(tmp, path)
            remove_path(old)
        else:
            os.replace(tmp, path)
    except BaseException:
        remove_path(tmp)
        raise


def write_bytes_atomic(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns ``path``."""
    path = Path(path)
    with staged(path) as tmp:
        tmp.write_bytes(data)
    return path


def write_text_atomic(path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically; returns ``path``."""
    return write_bytes_atomic(path, text.encode("utf-8"))
