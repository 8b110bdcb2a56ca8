"""The ``abacus`` command line (:func:`main`); one module per command."""
from abacus.cli.app import main

__all__ = ["main"]
