"""Every Python started with this folder on ``PYTHONPATH`` and ``PIGE_TEST_PROCESSOR_SEED`` set answers NumPy's
eigen-problems as another processor could (``tests/another_processor.py``); tests/test_docs_blocks.py runs docs
pages so.  Without the variable it does nothing."""

import os
import sys

_SEED = os.environ.get("PIGE_TEST_PROCESSOR_SEED")
if _SEED:
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import another_processor

    another_processor.install(int(_SEED))
