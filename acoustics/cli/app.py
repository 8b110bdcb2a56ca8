"""The ``abacus`` command line. The only layer (with the tests) that joins acoustics and
processing as peers; user errors end in one message and exit status 2, never a traceback.

One module per command (``acoustics/cli/<command>.py``), each with ``add_parser(sub)`` and
``command(args)``; this module builds the parser and is the error boundary.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import warnings

__all__ = ["main", "build_parser", "COMMANDS"]

#: sub-commands in the order ``abacus --help`` lists them
COMMANDS = ("run", "scene", "beams", "simulate", "image", "count", "experiment", "view")


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"warning: {message}", file=sys.stderr)


def _version() -> str:
    from acoustics import __version__
    return f"abacus {__version__}"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="abacus", description="The abacus command line: simulate "
                                "the ABACUS multibeam sonar in a ray-traced scene and process its "
                                "echoes into images, detections and counts.")
    p.add_argument("--version", action="version", version=_version())
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"acoustics.cli.{name}").add_parser(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)   # --help and --version end here, before any heavy import
    from processing.config import ConfigError
    from processing.dataset import DatasetError
    from processing.noise import NoiseEstimateError

    from acoustics.cli.common import UsageError
    warnings.showwarning = _show_warning
    try:
        return int(args.func(args) or 0)
    except (ConfigError, DatasetError, NoiseEstimateError, UsageError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of stdout went away (`abacus beams --json | head`): not an error of ours
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
