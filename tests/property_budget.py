"""How many examples a costly property test (hypothesis) draws: all of them under ``make test-slow``, a third in
``make test``.

``make test-slow`` sets ``PIGE_TEST_SLOW=1``: each test then draws the count it names (``examples(400)``: 400).  The
default suite draws a third of it, at least 50: the same property on fewer random cases per run (hypothesis draws
new ones at every run, so CI's runs together still cover what the full count does in one).  Used only where the
examples cost seconds (issue 46: ``make test`` within 5 minutes); measured by ``tests/cpu_report.py``.
"""

from __future__ import annotations

import os

#: ``make test-slow`` (every study and every example).
SLOW = os.environ.get("PIGE_TEST_SLOW", "") == "1"


def examples(full: int) -> int:
    """``full`` under ``make test-slow``, else a third of it (at least 50)."""
    return full if SLOW else max(full // 3, 50)
