"""The ``abacus`` command line. The only layer (with the tests) that joins acoustics and
processing as peers; every error a user can cause ends in one message and a documented exit
status (0 ok, 1 internal error — traceback in a log —, 2 bad input or option, 3 too large for
the memory or disk limits, 5 the machine refused a write, 130 interrupted, 143 terminated),
never a traceback, never a half-written output.

One module per command (``abacus/cli/<command>.py``), each with ``add_parser(sub)`` and
``command(args)``; this module builds the parser and is the error boundary.
"""
from __future__ import annotations

import argparse
import gc
import importlib
import sys
import threading
import warnings
from pathlib import Path

__all__ = ["main", "build_parser", "COMMANDS"]

#: sub-commands in the order ``abacus --help`` lists them
COMMANDS = ("run", "scene", "beams", "simulate", "image", "count", "targets", "track", "sv", "convert", "experiment",
            "dataset", "view")


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"warning: {message}", file=sys.stderr)


def _version() -> str:
    from acoustics import __version__
    return f"abacus {__version__}"


class _Parser(argparse.ArgumentParser):
    """argparse, with a bad option as one line (what is wrong and where help is), status 2; a
    mistyped command or choice gets the closest accepted one ("did you mean 'run'?")."""

    def error(self, message):
        self.exit(2, f"error: {self.prog}: {message}{_did_you_mean(message)} (see `{self.prog} --help`)\n")


def _did_you_mean(message: str) -> str:
    """"; did you mean 'X'?" for argparse's "invalid choice: 'Y' (choose from ...)" when an
    accepted choice is close to Y (difflib), else ""."""
    import difflib
    import re
    m = re.search(r"invalid choice: '((?:[^'\\]|\\.)*)' \(choose from (.*)\)", message)
    if m is None:
        return ""
    choices = [c.strip().strip("'\"") for c in m.group(2).split(",")]
    close = difflib.get_close_matches(m.group(1), [c for c in choices if c], n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="abacus", description="The abacus command line: simulate "
                                "the ABACUS multibeam sonar in a ray-traced scene and process its "
                                "echoes into images, detections and counts.")
    p.add_argument("--version", action="version", version=_version())
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)
    for name in COMMANDS:
        importlib.import_module(f"abacus.cli.{name}").add_parser(sub)
    return p


#: exit statuses (docs/reliability.md)
EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_RESOURCES, EXIT_IO = 0, 1, 2, 3, 5
EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread like KeyboardInterrupt for SIGINT."""


def _log_dir():
    from acoustics.sonar.cache import cache_dir
    folder = cache_dir()
    if folder is None:
        import tempfile
        return Path(tempfile.gettempdir()) / "abacus-logs"
    return folder / "logs"


def _log_traceback(exc) -> str:
    """Write the traceback of an unexpected error to a log file; return where (or why not)."""
    import datetime
    import os
    import traceback
    try:
        folder = _log_dir()
        folder.mkdir(parents=True, exist_ok=True)
        stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
        path = folder / f"abacus-{stamp}-{os.getpid()}.log"
        path.write_text("abacus " + " ".join(sys.argv[1:]) + "\n\n"
                        + "".join(traceback.format_exception(exc)))
        return str(path)
    except OSError as log_exc:
        return f"(the log could not be written: {log_exc.strerror})"


def _clean_up(message: str | None = None):
    """Temporaries removed, ``message`` on stderr, streams flushed: how every interrupted
    command ends."""
    from processing.base.atomic import remove_active
    remove_active()
    if message:
        print(message, file=sys.stderr)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    # the interrupt is handled: CPython still records it as unhandled if it left an eval() or
    # exec() of a string on its way here (namedtuple and dataclass definitions run one while
    # modules load), and then ends `python -m abacus` by SIGINT instead of this status; a new
    # evaluation of a string clears that record (CPython 3.11–3.13)
    exec("")


def _end_now(code: int, message: str | None = None):
    """Leave at once, where the command cannot end itself in time (a second signal; 5 s after
    the first): temporaries removed, then the signal ends the process by its default action —
    which a shell reports as 128 + the signal (130, 143).
    From another thread than the main one (the watchdog), which may not change a signal's
    action, SIGKILL ends it."""
    import os
    import signal
    import threading
    _clean_up(message)
    if threading.current_thread() is threading.main_thread():
        signum = signal.SIGINT if code == EXIT_INTERRUPTED else signal.SIGTERM
        signal.signal(signum, signal.SIG_DFL)
        signal.raise_signal(signum)
    os.kill(os.getpid(), signal.SIGKILL)


# the signal this process has received, as (exit status, word): a KeyboardInterrupt raised
# inside C code that swallows it (matplotlib's drawing does) surfaces as an unrelated error
# with no trace of the signal; the interrupt still decides how the process ends
_RECEIVED: list = []


def _install_signal_handlers():
    """SIGINT raises KeyboardInterrupt and SIGTERM _Terminated in the main thread; a second
    signal, or 5 s without the first one having ended the process, ends it at once
    (:func:`_end_now`)."""
    import signal
    import threading

    def watchdog(signum, code, message):
        # the signal again, in the main thread: its handler ends the process by the signal's
        # default action (128 + the signal); where the main thread runs no Python for another
        # second (inside a compiled call), SIGKILL from here
        def expire():
            main = threading.main_thread()
            if main.is_alive():
                signal.pthread_kill(main.ident, signum)
                main.join(1.0)
            _end_now(code, message)
        timer = threading.Timer(5.0, expire)
        timer.daemon = True
        timer.start()

    state = {"seen": False, "held": False}

    def handler(signum, frame):
        with _SWALLOWED_LOCK:
            again = _SWALLOWED.pop(signum, None)    # the interrupt a finaliser swallowed
            if again is not None and (_inside_hook(frame) or _inside_compiler(frame)):
                _SWALLOWED[signum] = "pending"      # raised here, it would be dropped again
                return
        if again is not None:
            raise KeyboardInterrupt if signum == signal.SIGINT else _Terminated()
        code = EXIT_INTERRUPTED if signum == signal.SIGINT else EXIT_TERMINATED
        word = "interrupted" if signum == signal.SIGINT else "terminated"
        atomic = sys.modules.get("processing.base.atomic")
        if state["held"] and not (atomic is not None and atomic.holding_interrupts()):
            state["held"] = False       # the held signal, raised again as the library write ended
            raise KeyboardInterrupt if signum == signal.SIGINT else _Terminated()
        if state["seen"]:
            _end_now(code, word)
        state["seen"] = True
        _RECEIVED.append((code, word))
        watchdog(signum, code, word)
        if atomic is not None and atomic.holding_interrupts():
            # inside a library write that an exception would leave stuck on its own locks:
            # raised when the write ends (processing.base.atomic.interrupts_held)
            state["held"] = True
            atomic.hold_signal(signum)
            return
        if _inside_compiler(frame):
            # raised inside numba's or llvmlite's Python code (a kernel compiled or loaded from
            # the cache, an LLVM object's finaliser), the interrupt left a dispatcher half made,
            # and the next call of that kernel crashed the process (exit -11, 7 of 1,550 SIGINTs
            # in the first synthesis of `abacus simulate` on a loaded machine): raised again,
            # by the thread that re-sends a swallowed interrupt, once the main thread is out
            _deliver_later(signum)
            return
        raise KeyboardInterrupt if signum == signal.SIGINT else _Terminated()

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, handler)
        signal.signal(signal.SIGTERM, handler)
        sys.unraisablehook = _unraisable_ends_an_interrupt(sys.unraisablehook)


#: the signal of an interrupt a finaliser swallowed -> "pending" (to be sent to the main thread
#: again) or "sent", until the handler raises it anew; one signal in flight at a time
_SWALLOWED: dict = {}
_SWALLOWED_LOCK = threading.RLock()
#: the code of the unraisable hook (an interrupt raised while it runs would be dropped)
_HOOK_CODES: set = set()


#: packages whose Python code an exception raised at an arbitrary bytecode can leave in a state
#: that crashes a later call (their compiler, cache and LLVM bindings are not written for it)
_COMPILER_PACKAGES = ("numba", "llvmlite")


def _inside_compiler(frame) -> bool:
    while frame is not None:
        name = frame.f_globals.get("__name__", "")
        if name.split(".", 1)[0] in _COMPILER_PACKAGES:
            return True
        frame = frame.f_back
    return False


def _deliver_later(signum):
    """Mark ``signum`` as an interrupt to raise anew and start the thread that sends it to the
    main thread until the handler has raised it (:func:`_deliver_again`)."""
    with _SWALLOWED_LOCK:
        running = signum in _SWALLOWED
        _SWALLOWED[signum] = "pending"
    if not running:
        threading.Thread(target=_deliver_again, args=(signum,), daemon=True).start()


def _deliver_again(signum):
    """Send ``signum`` to the main thread, every 10 ms while it is "pending", until the handler
    has raised it (it pops the entry) or the main thread has ended."""
    import signal
    import time
    main = threading.main_thread()
    while main.is_alive():
        with _SWALLOWED_LOCK:
            state = _SWALLOWED.get(signum)
            if state is None:           # raised anew: done
                return
            if state == "pending":
                _SWALLOWED[signum] = "sent"
                signal.pthread_kill(main.ident, signum)
        time.sleep(0.01)


def _inside_hook(frame) -> bool:
    while frame is not None:
        if frame.f_code in _HOOK_CODES:
            return True
        frame = frame.f_back
    return False


def _unraisable_ends_an_interrupt(default_hook):
    """A hook for exceptions Python can only print and drop (raised in a finaliser, a GC
    callback): one of ours from a signal — the handler raised it while a ``__del__`` ran —
    still ends the command as that interrupt, instead of a traceback printed and the command
    going on (seen in the reliability probes: SIGINT during an experiment, during imports):
    a thread sends the signal to the main thread again until its handler has raised the
    interrupt anew outside this hook (inside it, it would be dropped too), where it ends the
    command as any interrupt does."""
    import signal

    def hook(unraisable):
        if _RECEIVED and unraisable.exc_type is not None and \
                issubclass(unraisable.exc_type, (KeyboardInterrupt, _Terminated)):
            signum = signal.SIGINT if _RECEIVED[0][0] == EXIT_INTERRUPTED else signal.SIGTERM
            _deliver_later(signum)
            return
        default_hook(unraisable)
    _HOOK_CODES.add(hook.__code__)
    return hook


def _ended_by_signal(exc):
    """When a signal has been received (or caused ``exc``): temporaries removed, its word
    printed, its exit status returned (the error it surfaced as is not the story). Else None."""
    cause = _signal_cause(exc) or (_RECEIVED[0] if _RECEIVED else None)
    if cause is None:
        return None
    _clean_up(cause[1])
    return cause[0]


def _signal_cause(exc):
    """(exit status, word) when ``exc`` was caused by an interrupt or termination, else None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, KeyboardInterrupt):
            return EXIT_INTERRUPTED, "interrupted"
        if isinstance(exc, _Terminated):
            return EXIT_TERMINATED, "terminated"
        exc = exc.__cause__ or exc.__context__
    return None


def main(argv=None) -> int:
    """Run one ``abacus`` command; every error a user can cause ends as one line on stderr and
    a documented exit status, never a traceback.

    ``argv`` None: the process' own command line (``abacus ...``, ``python -m acoustics``)."""
    # first of all: an interrupt while the command's modules load (SIGINT was a traceback
    # there, before the handlers) ends it as any interrupt does
    _install_signal_handlers()
    try:
        from abacus.clash import foreign_packages
        clash = foreign_packages()   # PyPI's acoustics / processing in our place (README, install)
        if clash:
            print(f"error: {clash}", file=sys.stderr)
            return EXIT_USAGE
        parser = build_parser()
        args = parser.parse_args(argv)   # --help and --version end here, before any heavy import
        # the process is the command's own (`abacus ...`, `python -m abacus`), not a program
        # that called main(argv): only then may a command start worker processes ("spawn"
        # would run an unguarded calling script again in each)
        args.standalone = argv is None
    except KeyboardInterrupt:
        _clean_up("interrupted")
        return EXIT_INTERRUPTED
    except _Terminated:
        _clean_up("terminated")
        return EXIT_TERMINATED
    status = _command(args)
    if args.standalone:
        # The command is over and its outputs are closed: what remains is the interpreter's
        # exit, whose final garbage collection walks every object the ≈ 1,900 imported modules
        # made (0.4–0.6 s, a sixth of a 100-ping run). Frozen objects are freed by reference
        # counting as the modules are torn down, but no longer traversed for cycles. Only for
        # the command's own process: a program that called main(argv) keeps its collector.
        gc.freeze()
    return status


def _command(args) -> int:
    try:
        def loaded(*errors):
            # an error class whose module was never imported cannot have been raised: the
            # classes are looked up when an error arrives, so that no command waits for
            # their modules before it starts (xarray, pydantic: ≈ 0.5 s, which `abacus run`
            # spends with its figure workers already importing matplotlib beside it)
            # (a module still being imported by another thread may lack its class yet)
            found = (getattr(sys.modules.get(module), name, None) for module, name in errors)
            return tuple(cls for cls in found if cls is not None)

        def user_errors():
            return loaded(("processing.base.config", "ConfigError"), ("processing.base.dataset", "DatasetError"),
                          ("processing.detection.noise", "NoiseEstimateError"),
                          ("abacus.cli.common", "UsageError"),
                          ("abacus.experiment", "ExperimentError"),
                          ("acoustics.paths.meshes", "MeshError"),
                          ("processing.base.files", "FileRefused"))
        warnings.showwarning = _show_warning
        try:
            from abacus.cli.extras import check_extras
            check_extras(args)       # the extras the arguments call for, before any work
            return int(args.func(args) or 0)
        except loaded(("processing.base.resources", "ResourceError")) as exc:
            if (code := _ended_by_signal(exc)) is not None:
                return code
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_RESOURCES
        except user_errors() as exc:
            # a reader that turns any exception into "damaged or truncated (...)" also turns an
            # interrupt landing inside a library into one: still the interrupt
            if (code := _ended_by_signal(exc)) is not None:
                return code
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_USAGE
        except ImportError as exc:   # an optional extra not installed: one line naming it
            from processing.base.extras import missing_extra
            missing = missing_extra(exc, f"abacus {args.command}")
            if missing is None:
                raise
            print(f"error: {missing}", file=sys.stderr)
            return EXIT_USAGE
        except BrokenPipeError:
            raise
        except OSError as exc:   # the machine refused: disk full, permission, read-only
            if (code := _ended_by_signal(exc)) is not None:   # an interrupt surfaced as an OSError
                return code
            what = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
            reason = exc.strerror or (str(exc).splitlines()[0][:200] if str(exc).strip() else "")
            print(f"error: {reason or 'the machine refused a write'}{what}: nothing was left "
                  f"half-written", file=sys.stderr)
            return EXIT_IO
        except MemoryError:
            print("error: out of memory (the estimate did not hold: please report it); nothing "
                  "was left half-written", file=sys.stderr)
            return EXIT_RESOURCES
    except KeyboardInterrupt:
        _clean_up("interrupted")
        return EXIT_INTERRUPTED
    except _Terminated:
        _clean_up("terminated")
        return EXIT_TERMINATED
    except BrokenPipeError:
        # the reader of stdout went away (`abacus beams --json | head`): not an error of ours
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as exc:  # a bug of ours: one line here, the traceback in a log
        # a signal landing inside a compiled (numba) kernel surfaces as a SystemError whose
        # cause is the KeyboardInterrupt / _Terminated our handlers raised: still a signal
        cause = _signal_cause(exc) or (_RECEIVED[0] if _RECEIVED else None)
        if cause is not None:
            _clean_up(cause[1])
            return cause[0]
        where = _log_traceback(exc)
        print(f"error: internal error ({exc.__class__.__name__}: {str(exc).splitlines()[0][:200] if str(exc) else ''}); "
              f"the traceback is in {where} — please report it", file=sys.stderr)
        return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
