"""``python -m pige_sym`` runs the ``pige`` command line."""

import sys

from pige_sym.cli import main

sys.exit(main())
