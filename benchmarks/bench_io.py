"""Reading large measurement files: time and peak memory of ``read_measurement``, in one run.

Writes a ``pige-rtest 1`` file of N rows (default 10^6; the nine columns ``pige simulate``
writes, numbers in ``repr``), then measures, each in a fresh Python process so that the
peak resident memory (``ru_maxrss``) belongs to that step alone:

* **floor**: reading the file's bytes into memory (``Path.read_bytes``), the I/O every reader pays;
* **reference**: ``numpy.fromstring`` of the file's numeric body, already in memory: NumPy's own
  text-to-float conversion (no validation, no line numbers), which the reader used until it got
  its own vectorised parser (:mod:`pige_sym.measurements.decimal_fields`);
* **read_measurement**: the validating reader (header checks, strict numbers, physical
  limits, duplicate rows), reading the file in chunks;
* **baseline**: an empty Python process importing NumPy and pige_sym (the memory every
  step starts from).

Peak memory is ``VmHWM`` of the step's own process (``ru_maxrss`` would include the
parent's size at fork).

``main()`` prints a markdown section; ``python benchmarks/bench_io.py [rows]``.
The target from the diagnosis issue: 10^6 rows in <= 2 s and <= 400 MB.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pige_sym.measurements.measurement import Measurement  # noqa: E402
from pige_sym.measurements.rtest_writer import header_text  # noqa: E402

STEP = r"""
import json, sys, time
import numpy as np
from pige_sym.measurements.rtest import read_measurement
path, what = sys.argv[1], sys.argv[2]
t0 = time.perf_counter()
if what == "bytes":
    n = len(open(path, "rb").read())
elif what == "floor":
    data = open(path, "rb").read()
    body = data[data.index(b"\nt_s,") + 1:]
    body = body[body.index(b"\n") + 1:]
    t0 = time.perf_counter()
    n = np.fromstring(body.replace(b"\n", b","), sep=",").size
elif what == "read":
    n = read_measurement(path).n_rows
else:
    n = 0
dt = time.perf_counter() - t0
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")][0].split()[1]  # this process only
print(json.dumps({"s": dt, "rss_mb": int(hwm) / 1024, "n": n}))
"""


def _write_file(path: Path, rows: int, *, text_column: bool = False) -> None:
    """A valid file of ``rows`` rows: the writer's header, then the body with ``%.17g`` (round-trips);
    ``text_column`` adds a last column ``status`` of short texts (as devices write)."""
    rng = np.random.default_rng(0)
    data = np.column_stack([np.arange(rows) * 0.01, rng.uniform(-30, 30, rows), rng.uniform(0, 360, rows),
                            rng.normal(scale=10.0, size=(rows, 3)), rng.uniform(-200, 200, size=(rows, 3))])
    data[0, 1:6] = 0.0
    head = Measurement(machine="wC'A'bXYZ(C1)t", ball_mm=np.array([120.0, 0.0, 80.0]), t_s=data[:1, 0],
                       angles_deg=data[:1, 1:3], deviation_um=data[:1, 3:6], rotary_axes=("A", "C"),
                       linear_mm=data[:1, 6:9], extra_columns={"status": ["ok"]} if text_column else {})
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(header_text(head))
        if not text_column:
            np.savetxt(fh, data, fmt="%.17g", delimiter=",")
            return
        for start in range(0, rows, 100_000):
            lines = [",".join(f"{v:.17g}" for v in row) for row in data[start : start + 100_000].tolist()]
            fh.write("".join(f"{line},{'ok' if k % 97 else 'spike'}\n" for k, line in enumerate(lines, start)))


def _step(path: Path, what: str) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", STEP, str(path), what], capture_output=True, text=True, check=True,
                         cwd=ROOT)
    return dict(json.loads(out.stdout))


def main(rows: int = 10**6) -> str:
    """Measure and return (and print) the markdown section."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.csv"
        t0 = time.perf_counter()
        _write_file(path, rows)
        write_s = time.perf_counter() - t0
        size_mb = path.stat().st_size / 2**20
        base = _step(path, "baseline")
        io_floor = _step(path, "bytes")
        floor = _step(path, "floor")
        read = _step(path, "read")
        _write_file(path, rows, text_column=True)
        read_text = _step(path, "read")
    assert read["n"] == rows == read_text["n"]
    ok_t = "met" if read["s"] <= 2.0 else "missed"
    ok_m = "met" if read["rss_mb"] <= 400 else "missed"
    text = "\n".join([
        f"## Reading a {rows:,}-row measurement file ({size_mb:.0f} MB)",
        "",
        "| step | time [s] | peak RSS [MB] |",
        "|---|---:|---:|",
        f"| baseline (python + numpy + pige_sym imported) | - | {base['rss_mb']:.0f} |",
        f"| floor: read the file's bytes | {io_floor['s']:.2f} | {io_floor['rss_mb']:.0f} |",
        f"| reference: numpy.fromstring of the body in memory (NumPy's parser) | {floor['s']:.2f} | "
        f"{floor['rss_mb']:.0f} |",
        f"| read_measurement (validating, chunked, vectorised parser) | {read['s']:.2f} | {read['rss_mb']:.0f} |",
        f"| the same with one more column of text (`status`) | {read_text['s']:.2f} | {read_text['rss_mb']:.0f} |",
        "",
        f"Reader / byte-read floor: {read['s'] / io_floor['s']:.1f}x; reader / NumPy's parser: "
        f"{read['s'] / floor['s']:.2f}x.  Target 2 s: {ok_t}; 400 MB: {ok_m}.  "
        f"(Writing the file took {write_s:.1f} s.)  The body is {rows * 9:,} values of 16–17 significant "
        "digits (``repr``), the worst case of the parser (each needs the double-double quotient).  A text "
        "column is kept verbatim as Python strings (one slice per row), which costs extra.",
        "",
    ])
    print(text)
    return text


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 10**6)
