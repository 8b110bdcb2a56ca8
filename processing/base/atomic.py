"""Atomic outputs: a file or folder appears under its final name complete, or not at all.

Everything abacus writes goes through :func:`staged`: the writer fills a temporary sibling
(``.NAME.tmp-<pid>-<random>``, hidden, in the same folder so the final rename is atomic on one
filesystem), which is renamed over the final name when the writer finishes and removed when it
fails or is interrupted. Temporaries left by a process that was killed (SIGKILL, power loss) are
recognised by their process id and removed by the next write to the same name; the temporaries
of the running process are listed in :data:`ACTIVE` so an interrupt handler can remove them.

A command that writes several outputs (a dataset, CSV tables, a folder of figures) writes them
all through one :func:`staged_set`: each to its temporary, and only when every one is complete
are they all renamed into place (signals held off for the few renames), so an error, a full disk
or an interrupt part-way leaves none of them.

A writer that fails because the filesystem is full (or over the process' file-size limit) fails
as :class:`OSError` ``ENOSPC`` (``EFBIG``) naming the output, whatever the library wrote it with
reported (HDF5 says only "NetCDF: HDF error"): :func:`disk_refusal`.
"""
from __future__ import annotations

import errno
import os
import re
import shutil
import uuid
from contextlib import contextmanager
from pathlib import Path

__all__ = ["staged", "staged_set", "StagedSet", "scratch", "write_bytes_atomic", "write_text_atomic",
           "remove_path", "remove_stale", "remove_active", "disk_refusal", "interrupts_held",
           "holding_interrupts", "hold_signal", "TMP_MARK", "ACTIVE"]

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
        try:
            yield tmp
        except Exception as exc:
            refusal = disk_refusal(exc, tmp, path)
            if refusal is None:
                raise
            remove_path(tmp)
            raise refusal from exc
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


#: free bytes below which a failed write is taken for a full filesystem (HDF5 and other C
#: writers report ENOSPC as a generic error; what they had written is still on the disk when
#: the failure is seen, so the filesystem is then (nearly) full)
FULL_BELOW_BYTES = 1 << 20


def _size(path: Path) -> int:
    try:
        if path.is_dir():
            return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
        return path.stat().st_size
    except OSError:
        return 0


def _file_size_limit() -> int | None:
    """The process' file size limit (RLIMIT_FSIZE) in bytes, or None when unlimited."""
    try:
        import resource
        soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        return None if soft == resource.RLIM_INFINITY or soft < 0 else int(soft)
    except (ImportError, AttributeError, OSError, ValueError):
        return None


#: errno values that mean the machine refused a write for want of room
_ROOM = {errno.ENOSPC, errno.EFBIG, getattr(errno, "EDQUOT", errno.ENOSPC)}


def disk_refusal(exc: BaseException, tmp: Path, path: Path) -> OSError | None:
    """The :class:`OSError` a failed write of ``path`` (into ``tmp``) stands for when the machine
    refused it for want of room — ``ENOSPC`` (the filesystem is full), ``EDQUOT``, ``EFBIG``
    (the process' file size limit) — else None (a bug or bad data: not for this to say).

    An ``OSError`` with one of those codes anywhere in the chain of ``exc`` is one; an error
    without a code (HDF5 reports a full disk as "NetCDF: HDF error") is one when the
    filesystem of ``tmp`` is found (nearly) full with the temporary still on it, or the
    temporary has reached the file size limit."""
    room = _room_error(exc)
    if room is not None:
        return OSError(room.errno, os.strerror(room.errno), str(path))
    if not isinstance(exc, Exception):       # an interrupt is not a refusal
        return None
    try:
        free = shutil.disk_usage(tmp.parent).free
    except OSError:
        free = None
    if free is not None and free < FULL_BELOW_BYTES:
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    limit = _file_size_limit()
    if limit is not None and _size(tmp) >= limit - FULL_BELOW_BYTES:
        return OSError(errno.EFBIG, os.strerror(errno.EFBIG), str(path))
    return None


class StagedSet:
    """Outputs written together: each to a temporary by :meth:`path`, all renamed into place by
    :meth:`commit` (see :func:`staged_set`)."""

    def __init__(self):
        self._staged: list = []     # (final path, temporary, tag)
        self._placed: list = []     # (final path, backup of what it replaced, or None)

    def path(self, final, *, suffix: str | None = None) -> Path:
        """A temporary to write ``final`` to (it does not exist yet; a writer may make a file
        or a folder there). It ends with ``final``'s own suffix (or ``suffix``), as some
        writers choose their format by it (``.zarr``, ``.png``)."""
        final = Path(final)
        if any(final == f for f, _, _ in self._staged):
            raise ValueError(f"{final} is staged twice")
        remove_stale(final.parent, final.name)
        tag = f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
        tmp = final.with_name(f".{final.name}{TMP_MARK}{tag}{final.suffix if suffix is None else suffix}")
        ACTIVE.add(tmp)
        self._staged.append((final, tmp, tag))
        return tmp

    def final_of(self, tmp) -> Path | None:
        """The output a temporary stands for (None: not one of this set's)."""
        tmp = str(tmp)
        for final, t, _ in self._staged:
            if tmp == str(t) or tmp.startswith(f"{t.parent}/.{t.name}"):   # a writer's own temporary
                return final
        return None

    def commit(self) -> None:
        """Rename every temporary over its final name. What an output replaces is kept aside
        until all are in place and comes back if a rename fails; SIGINT and SIGTERM are held off
        during the renames, and one that arrived meanwhile undoes them (the command then ends as
        interrupted, with the outputs as they were before it)."""
        missing = [f for f, t, _ in self._staged if not (t.exists() or t.is_symlink())]
        if missing:
            raise FileNotFoundError(errno.ENOENT, "the writer made no output", str(missing[0]))
        try:
            with _signals_held():
                for final, tmp, tag in self._staged:
                    backup = None
                    if final.exists() or final.is_symlink():
                        backup = final.with_name(f".{final.name}.old-{tag}")
                        os.replace(final, backup)
                    self._placed.append((final, backup))
                    os.replace(tmp, final)
            # a signal held off during the renames is raised here, and undoes them
        except BaseException:
            self._undo()
            raise
        for _, tmp, _ in self._staged:
            ACTIVE.discard(tmp)
        placed, self._placed = self._placed, []
        for _, backup in placed:
            if backup is not None:
                remove_path(backup)

    def _undo(self) -> None:
        for final, backup in reversed(self._placed):
            remove_path(final)
            if backup is not None and (backup.exists() or backup.is_symlink()):
                os.replace(backup, final)
        self._placed = []

    def abort(self) -> None:
        """Remove every temporary (and undo what :meth:`commit` had placed)."""
        self._undo()
        for _, tmp, _ in self._staged:
            remove_path(tmp)
            ACTIVE.discard(tmp)


@contextmanager
def _signals_held():
    """SIGINT and SIGTERM blocked in this (the main) thread for the block; one that arrives
    meanwhile is delivered when it ends."""
    import signal
    import threading
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextmanager
def staged_set():
    """Write several outputs all or nothing.

    Yields a :class:`StagedSet`: ``outputs.path(final)`` gives the temporary to write each
    output to; when the block ends without an error, every output is renamed into place at
    once (:meth:`StagedSet.commit`); when it fails or is interrupted, every temporary is removed
    and no output appears (one that existed stays as it was). A write that failed for want of
    room is raised as :class:`OSError` (``ENOSPC``, ``EFBIG``) naming its output
    (:func:`disk_refusal`)::

        with staged_set() as outputs:
            write_tree(tree, outputs.path(out))
            write_csv(tree, outputs.path(csv))
    """
    outputs = StagedSet()
    try:
        try:
            yield outputs
        except Exception as exc:
            for final, tmp, _ in outputs._staged:
                refusal = disk_refusal(exc, tmp, final)
                if refusal is not None:
                    failed = outputs.final_of(getattr(_room_error(exc), "filename", None) or "") or final
                    raise OSError(refusal.errno, refusal.strerror, str(failed)) from exc
            raise
        outputs.commit()
    except BaseException:
        outputs.abort()
        raise


def _room_error(exc: BaseException) -> OSError | None:
    """The OSError for want of room in the chain of ``exc``, if any."""
    seen, e = set(), exc
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if isinstance(e, OSError) and e.errno in _ROOM:
            return e
        e = e.__cause__ or e.__context__
    return None


#: library writes in progress that an interrupt must not break into (depth), and the signal
#: that arrived meanwhile
_HELD = {"depth": 0, "signal": None}


@contextmanager
def interrupts_held():
    """Run a library's write whose clean-up an exception raised between two of its statements
    would leave stuck: xarray's netCDF writer takes its file locks one by one, an interrupt
    raised in between leaves one held, and the writer's ``finally`` then waits on it for ever
    (a SIGTERM at the end of a write waited for the 5 s watchdog, then was killed).

    An interrupt handler that honours it (the ``abacus`` command's: it asks
    :func:`holding_interrupts`) records the signal with :func:`hold_signal` instead of raising
    it; the signal is raised again when the block ends — the temporary being written is then
    removed as after any interrupt. Only the main thread is held."""
    import threading
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _HELD["depth"] += 1
    try:
        yield
    finally:
        _HELD["depth"] -= 1
        signum = _HELD["signal"]
        if _HELD["depth"] == 0 and signum is not None:
            _HELD["signal"] = None
            import signal
            signal.raise_signal(signum)      # its handler raises the interrupt here


def holding_interrupts() -> bool:
    """Whether the main thread is inside :func:`interrupts_held`."""
    return _HELD["depth"] > 0


def hold_signal(signum: int) -> None:
    """Record a signal that arrived inside :func:`interrupts_held`, to raise when it ends."""
    _HELD["signal"] = signum


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
