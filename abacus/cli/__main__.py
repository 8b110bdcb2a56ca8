"""``python -m abacus.cli``: the ``abacus`` command line."""
import sys

from abacus.cli.app import main

sys.exit(main())
