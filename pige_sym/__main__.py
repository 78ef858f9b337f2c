"""``python -m pige_sym`` runs the ``pige`` command line."""

import sys

from .cli import main

sys.exit(main())
