"""One gate for every file a user supplies: where it may lie, what it must be, how much of it.

A scene names files (meshes, height grids, a motion log, a noise-only dataset) and commands take
files on their command line. Each one goes through :func:`check_file` (and, to read it,
:func:`read_bytes` or :func:`read_text`) before anything else touches it:

1. **Where.** A path written in a scene resolves against the scene file's folder and, symbolic
   links followed, must lie in that folder or below it — a scene may not read ``/etc/passwd``,
   ``../other-project/`` or another user's data. The person running the command (not the scene)
   lifts this with the environment variable ``ABACUS_ALLOW_OUTSIDE_FILES=1``. A path the user
   named on the command line has no such folder (``folder=None``).
2. **What.** It exists and is a regular file: a folder, a FIFO (whose ``open`` would wait for a
   writer for ever), a device (``/dev/zero`` never ends) or a socket is refused from
   :func:`os.stat`, before any ``open``; the file is then opened non-blocking and checked again
   on its descriptor, so a file swapped for a pipe in between is refused too.
3. **How much.** Its size is checked against a cap before a byte is read, and no more than the
   cap is ever read.
4. **Its text.** :func:`read_text` decodes with a declared encoding (a byte-order mark, UTF-8,
   UTF-16 or UTF-32, is honoured and removed) and refuses binary data (a NUL byte) and bytes the
   encoding cannot decode, naming the line and column.

Every refusal is a :class:`FileRefused`: one line naming the place that names the file (the
scene file and line, when given), the key, the file, what is wrong and what is accepted. No
message ever quotes the contents of a file — callers that parse a file report line and column,
never the text found there, since the file may not be the user's own.

Standard library only: every layer may use it.
"""
from __future__ import annotations

import codecs
import os
import stat
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ALLOW_OUTSIDE_ENV", "FileRefused", "UserFile", "outside_allowed", "check_file",
           "read_bytes", "read_text", "line_column"]

#: set to 1 (or true, yes) to let scenes read files outside their own folder
ALLOW_OUTSIDE_ENV = "ABACUS_ALLOW_OUTSIDE_FILES"


class FileRefused(ValueError):
    """A user-supplied file that the gate refuses; the message is one complete line.

    Attributes
    ----------
    path : Path or None
        The file as it would have been opened.
    key : str or None
        The scene key or option that names it.
    """

    def __init__(self, message: str, *, path: Path | None = None, key: str | None = None):
        super().__init__(message)
        self.path = path
        self.key = key


def outside_allowed() -> bool:
    """Whether the person running the command lets scenes read files outside their folder
    (``ABACUS_ALLOW_OUTSIDE_FILES=1``)."""
    return os.environ.get(ALLOW_OUTSIDE_ENV, "").strip().lower() in ("1", "true", "yes")


@dataclass(frozen=True)
class UserFile:
    """A file the gate let through.

    Attributes
    ----------
    path : Path
        Where it is opened (the scene's folder joined with the name written, or the name).
    name : str
        The path as the user or the scene wrote it.
    size : int
        Bytes (0 for a folder let through with ``allow_folder``).
    is_folder : bool
    prefix : str
        ``"<where>: <key>: "`` for messages about it.
    """

    path: Path
    name: str
    size: int
    is_folder: bool
    prefix: str

    def refuse(self, message: str) -> FileRefused:
        """A :class:`FileRefused` about this file (``message`` follows the prefix)."""
        return FileRefused(f"{self.prefix}{message}", path=self.path)


def _prefix(where, key) -> str:
    return "".join(f"{part}: " for part in (where, key) if part)


def _kind_of(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _fmt_size(n: float) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{int(n)} bytes"


def check_file(name, *, folder=None, max_bytes: int | None, what: str = "file",
               key: str | None = None, where: str | None = None, accepts: str | None = None,
               allow_folder: bool = False, folder_name: str = "the scene's folder") -> UserFile:
    """Check a user-supplied file without reading it.

    Parameters
    ----------
    name : str or Path
        The path as written (in a scene, relative to ``folder``; on a command line, relative to
        the working directory).
    folder : str or Path, optional
        The folder the file must lie in (symbolic links followed) and relative paths resolve
        against: the scene file's folder. None: a path the user named on the command line,
        taken as it is.
    max_bytes : int or None
        The most bytes the file may hold; None: no cap here (the reader bounds its memory
        itself, as :func:`processing.base.dataset.open_tree` does).
    what : str
        What the file is, for messages ("motion file", "mesh file").
    key : str, optional
        The scene key or option naming it ("sonar.motion.file"), for messages.
    where : str, optional
        The place naming it ("scene.yaml:12"), for messages.
    accepts : str, optional
        What is accepted, for messages ("a CSV file of motion samples"); default ``what``.
    allow_folder : bool
        Let a folder through (a Zarr store is one).
    folder_name : str
        What ``folder`` is, for messages ("the scene's folder", "the working directory").

    Returns
    -------
    UserFile

    Raises
    ------
    FileRefused
        Outside the folder, missing, not a regular file, too large.
    """
    prefix = _prefix(where, key)
    accepts = accepts or f"a {what}"
    text = os.fspath(name) if isinstance(name, (str, os.PathLike)) else None
    if not text or not text.strip() or "\x00" in text:
        raise FileRefused(f"{prefix}{what}: give a file name ({accepts})", key=key)
    path = Path(text)
    if folder is not None and not path.is_absolute():
        path = Path(folder) / path
    shown = repr(text)
    if folder is not None and not outside_allowed():
        try:
            home = Path(folder).resolve()
            resolved = path.resolve()
        except (OSError, RuntimeError):   # a loop of symbolic links
            raise FileRefused(f"{prefix}{what} {shown}: cannot be resolved (a loop of symbolic "
                              f"links); give {accepts}", path=path, key=key) from None
        if not resolved.is_relative_to(home):
            raise FileRefused(f"{prefix}{what} {shown} lies outside {folder_name} {home}; it "
                              f"must be in it or below it (set {ALLOW_OUTSIDE_ENV}=1 to allow "
                              f"other places)", path=path, key=key)
    try:
        st = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        relative = (f"paths are relative to {folder_name}" if folder is not None
                    else "paths are relative to the working directory")
        raise FileRefused(f"{prefix}{what} {shown} not found (looked for {path}); {relative}",
                          path=path, key=key) from None
    except PermissionError:
        raise FileRefused(f"{prefix}{what} {shown}: permission denied; give {accepts} you may "
                          f"read", path=path, key=key) from None
    except (OSError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or exc.__class__.__name__
        raise FileRefused(f"{prefix}{what} {shown}: cannot be read ({reason}); give {accepts}",
                          path=path, key=key) from None
    if stat.S_ISDIR(st.st_mode) and allow_folder:
        return UserFile(path, text, 0, True, prefix)
    if not stat.S_ISREG(st.st_mode):
        raise FileRefused(f"{prefix}{what} {shown} is {_kind_of(st.st_mode)}, not a regular file; "
                          f"give {accepts}", path=path, key=key)
    if max_bytes is not None and st.st_size > max_bytes:
        raise FileRefused(f"{prefix}{what} {shown} is {_fmt_size(st.st_size)}; a {what} may hold "
                          f"at most {_fmt_size(max_bytes)}", path=path, key=key)
    return UserFile(path, text, int(st.st_size), False, prefix)


def read_bytes(name, *, max_bytes: int, **gate) -> tuple[UserFile, bytes]:
    """Check a user-supplied file (:func:`check_file`, same arguments) and read it whole.

    The file is opened non-blocking and checked again on its descriptor (a regular file, within
    the cap), and at most ``max_bytes`` are read.

    Returns
    -------
    (UserFile, bytes)

    Raises
    ------
    FileRefused
    """
    gate.pop("allow_folder", None)
    f = check_file(name, max_bytes=max_bytes, **gate)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(f.path, flags)
    except OSError as exc:
        raise f.refuse(f"{gate.get('what', 'file')} {f.name!r}: cannot be opened "
                       f"({exc.strerror or exc.__class__.__name__})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise f.refuse(f"{gate.get('what', 'file')} {f.name!r} is {_kind_of(st.st_mode)}, "
                           f"not a regular file")
        chunks, total = [], 0
        while True:
            chunk = os.read(fd, min(1 << 22, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > max_bytes:
                raise f.refuse(f"{gate.get('what', 'file')} {f.name!r} grew past "
                               f"{_fmt_size(max_bytes)} while being read")
    except OSError as exc:
        raise f.refuse(f"{gate.get('what', 'file')} {f.name!r}: cannot be read "
                       f"({exc.strerror or exc.__class__.__name__})") from None
    finally:
        os.close(fd)
    return f, b"".join(chunks)


_BOMS = ((codecs.BOM_UTF32_LE, "utf-32-le"), (codecs.BOM_UTF32_BE, "utf-32-be"),
         (codecs.BOM_UTF8, "utf-8"), (codecs.BOM_UTF16_LE, "utf-16-le"),
         (codecs.BOM_UTF16_BE, "utf-16-be"))


def line_column(data, offset: int) -> tuple[int, int]:
    """(line, column), both from 1, of position ``offset`` in ``data`` (bytes or str)."""
    nl = b"\n" if isinstance(data, bytes) else "\n"
    line = data.count(nl, 0, offset) + 1
    return line, offset - (data.rfind(nl, 0, offset) + 1) + 1


def read_text(name, *, max_bytes: int, encoding: str = "utf-8", **gate) -> tuple[UserFile, str]:
    """Check a user-supplied text file (:func:`check_file`, same arguments), read and decode it.

    A byte-order mark (UTF-8, UTF-16, UTF-32) decides the encoding and is removed; otherwise
    ``encoding`` is used. Line ends are kept as they are.

    Returns
    -------
    (UserFile, str)

    Raises
    ------
    FileRefused
        As :func:`read_bytes`; binary data (a NUL byte) or bytes the encoding cannot decode,
        with the line and column.
    """
    f, data = read_bytes(name, max_bytes=max_bytes, **gate)
    what = gate.get("what", "file")
    accepts = gate.get("accepts") or f"a {what}"
    enc, body = encoding, data
    for bom, bom_enc in _BOMS:
        if data.startswith(bom):
            enc, body = bom_enc, data[len(bom):]
            break
    if enc == encoding and b"\x00" in body:
        line, col = line_column(body, body.index(b"\x00"))
        raise f.refuse(f"{f.path}:{line}:{col}: binary data (a NUL byte), not {encoding.upper()} "
                       f"text; give {accepts}")
    try:
        text = body.decode(enc)
    except UnicodeDecodeError as exc:
        line, col = line_column(body, exc.start)
        raise f.refuse(f"{f.path}:{line}:{col}: not {enc.upper()} text (bytes it cannot "
                       f"decode); give {accepts}") from None
    if "\x00" in text:
        line, col = line_column(text, text.index("\x00"))
        raise f.refuse(f"{f.path}:{line}:{col}: binary data (a NUL character), not text; give "
                       f"{accepts}")
    return f, text
