"""``python -m acoustics`` (or ``python -m acoustics.cli``): the ``abacus`` command line."""
import sys

from acoustics.cli.app import main

sys.exit(main())
