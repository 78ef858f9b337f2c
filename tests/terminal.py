"""Commands started as a shell starts a foreground command: SIGINT at its default.

A shell without job control starts a background command (``make test &`` in a script, ``nohup``) with SIGINT
ignored, and an ignored signal stays ignored across ``fork`` and ``exec``: the test runner, its workers and every
command they start then ignore SIGINT, so a test that presses Ctrl-C (``send_signal(SIGINT)``) would see the
command run to its end (exit 0) instead of being interrupted (130).  :func:`as_from_a_terminal` puts SIGINT back to
its default before the command is executed, as an interactive shell does, so that Python installs its
``KeyboardInterrupt`` handler in the command whatever started the test runner.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

_EXEC_WITH_DEFAULT_SIGINT = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
                             "os.execv(sys.argv[1], sys.argv[1:])")


def as_from_a_terminal(cmd: Sequence[str]) -> list[str]:
    """``cmd`` (its first word an executable path) run with SIGINT at its default (module docstring)."""
    return [sys.executable, "-I", "-S", "-c", _EXEC_WITH_DEFAULT_SIGINT, *cmd]
