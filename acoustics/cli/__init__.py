"""The ``abacus`` command line (:func:`main`); one module per command."""
from acoustics.cli.app import main

__all__ = ["main"]
