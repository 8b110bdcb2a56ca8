"""``python -m acoustics``: the ``abacus`` command line."""
import sys

from acoustics.cli.app import main

sys.exit(main())
