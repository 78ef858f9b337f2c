"""``python -m pige_sym`` runs the ``pige`` command line."""

import sys

try:
    from pige_sym.cli import main

    status = main()
except KeyboardInterrupt:  # before main() took over SIGINT, or after it gave it back
    print("pige: interrupted", file=sys.stderr)
    status = 130
sys.exit(status)
