"""CPU seconds per test file, as docs/testing.md tables them: a pytest plugin, and the table it gives.

The plugin records, for every test (set-up, call and tear-down), the wall time and the CPU seconds of the test
process and of the commands it started and waited for (``resource.getrusage``: ``RUSAGE_SELF`` +
``RUSAGE_CHILDREN``), so another job's CPU on a shared machine does not count (its load still stretches the
wall time); and for each process its collection and its whole session.  One JSON line per test, one file per
pytest-xdist process: ``<CPU_REPORT>.<worker>.jsonl``.  A module-scoped fixture counts with the first test that
asks for it::

    PYTHONPATH=tests PYTEST_ADDOPTS="-p cpu_report" CPU_REPORT=/tmp/cpu make test
    python tests/cpu_report.py /tmp/cpu          # CPU and wall per file, the costliest first
"""

from __future__ import annotations

import collections
import glob
import json
import os
import resource
import sys
import time
from collections.abc import Generator
from typing import IO, Any

import pytest

_out: list[IO[str]] = []
_start: dict[str, float] = {}


def _cpu() -> tuple[float, float]:
    me, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime, children.ru_utime + children.ru_stime


def _write(record: dict[str, Any]) -> None:
    if not _out:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        _out.append(open(f"{os.environ.get('CPU_REPORT', 'cpu_report')}.{worker}.jsonl", "a", encoding="utf-8"))
    _out[0].write(json.dumps(record) + "\n")
    _out[0].flush()


def _since_start(kind: str) -> None:
    me, children = _cpu()
    _write({"kind": kind, "wall": time.time() - _start["wall"], "self": me - _start["self"],
            "children": children - _start["children"]})


def pytest_sessionstart(session: pytest.Session) -> None:
    _start["wall"] = time.time()
    _start["self"], _start["children"] = _cpu()


def pytest_collection_finish(session: pytest.Session) -> None:
    _since_start("collect")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None, None, None]:
    wall, (me, children) = time.time(), _cpu()
    yield
    me2, children2 = _cpu()
    _write({"kind": "test", "id": item.nodeid, "file": item.nodeid.split("::")[0], "wall": time.time() - wall,
            "self": me2 - me, "children": children2 - children})


def pytest_sessionfinish(session: pytest.Session) -> None:
    _since_start("session")


def table(prefix: str) -> str:
    """Tests, CPU and wall seconds per file from the records under ``prefix``, the costliest first."""
    records = [json.loads(line) for name in glob.glob(prefix + ".*.jsonl") for line in open(name, encoding="utf-8")]
    files: dict[str, list[float]] = collections.defaultdict(lambda: [0, 0.0, 0.0])
    for r in records:
        if r["kind"] == "test":
            row = files[r["file"]]
            row[0] += 1
            row[1] += r["self"] + r["children"]
            row[2] += r["wall"]
    lines = [f"{'file':48} {'tests':>5} {'CPU [s]':>8} {'wall [s]':>8}"]
    lines += [f"{f:48} {n:5d} {cpu:8.1f} {wall:8.1f}" for f, (n, cpu, wall) in sorted(files.items(),
                                                                                        key=lambda x: -x[1][1])]
    lines.append(f"{'tests':48} {sum(int(r[0]) for r in files.values()):5d} "
                 f"{sum(r[1] for r in files.values()):8.1f} {sum(r[2] for r in files.values()):8.1f}")
    lines += [f"{r['kind']:48} {'':5} {r['self'] + r['children']:8.1f} {r['wall']:8.1f}" for r in records
              if r["kind"] != "test"]
    return "\n".join(lines)


if __name__ == "__main__":
    print(table(sys.argv[1]))
