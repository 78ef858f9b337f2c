"""Issue 33, files: hangs, clobbers and the operating system's refusals.

- every input slot of every command refuses a FIFO, a folder and an unreadable file before reading (one helper,
  :func:`pige_sym.files.open_regular_file`; sniffing a file's kind with :func:`pige_sym.files.peek_input` never
  blocks);
- an output folder that is read-only is refused before the long work;
- ``pige report --out DIR`` replaces an earlier report only with ``--force`` and leaves other files alone;
- an interrupt during ``pige report`` leaves the old folder or the new one, never part of one.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
from terminal import as_from_a_terminal

from pige_sym.cli.main import main
from pige_sym.errors import FileFormatError
from pige_sym.files import peek_input, read_input_bytes, staged_folder
from testdata import figures_not_drawn, refused_in_one_line

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
PNG_END = b"IEND\xaeB`\x82"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    code = main(list(argv))
    return code, capsys.readouterr().err


refused = refused_in_one_line


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with a measurement, a parameter file and an NC program (valid), for the slots not under test."""
    d = tmp_path_factory.mktemp("inputs")
    assert main(["simulate", "--out", str(d / "run.csv"), "--seed", "1", "--points", "12"]) == 0
    assert main(["program", "--trajectory", "cone-frustum", "--out", str(d / "prog.mpf")]) == 0
    (d / "params.json").write_text('{"machine": "wC\'A\'bXYZ(C1)t", "pige": {"EY0A": 1, "EZ0A": 1, "EB0A": 1, '
                                   '"EC0A": 1, "EX0C": 1, "EY0C": 1, "EA0C": 1, "EB0C": 1}}')
    return d


def _slots(d: Path, bad: str, out: Path) -> list[list[str]]:
    """Every input slot of every command, with ``bad`` in it."""
    run_csv, prog, params, tol = str(d / "run.csv"), str(d / "prog.mpf"), str(d / "params.json"), \
        str(EXAMPLES / "tolerances.json")
    probe = ["--format", "linuxcnc", "--sphere-radius", "12.7", "--stylus-radius", "1.5"]
    return [
        ["identify", bad], ["identify", run_csv, bad], ["diagnose", bad], ["diagnose", run_csv, bad],
        ["check", bad, "--tolerances", tol], ["check", run_csv, "--tolerances", bad],
        ["report", bad, "--out", str(out / "r1")], ["report", run_csv, "--out", str(out / "r2"), "--program", bad],
        ["report", run_csv, "--out", str(out / "r3"), "--tolerances", bad],
        ["report", run_csv, "--out", str(out / "r4"), "--compare", bad, run_csv],
        ["compensate", bad, "--params", params, "--out", str(out / "o.mpf")],
        ["compensate", prog, "--params", bad, "--out", str(out / "o.mpf")],
        ["history", "add", bad, "--machine-id", "M", "--db", str(out / "h.db")],
        ["plan", "--grade", bad], ["compare", bad, run_csv], ["compare", run_csv, bad],
        ["program", "--trajectory", bad, "--out", str(out / "p.mpf")],
        ["simulate", "--trajectory", bad, "--out", str(out / "s.csv")],
        ["simulate", "--pige", bad, "--out", str(out / "s2.csv")],
        ["import-probe", bad, *probe, "--out", str(out / "i.csv")],
        ["acquire", "--port", "socket://127.0.0.1:9", "--program", bad, "--out", str(out / "a.csv")],
        ["acquire", "--port", "socket://127.0.0.1:9", "--nest", bad, "--out", str(out / "a2.csv")],
    ]


class _Rescuer:
    """Opens a FIFO for writing after ``after`` seconds if it is still needed: a reader that blocked on the FIFO
    then reads end-of-file and the test fails instead of hanging."""

    def __init__(self, fifo: Path, after: float = 20.0) -> None:
        self.fifo, self.after, self.rescued, self.done = fifo, after, False, threading.Event()
        self.thread = threading.Thread(target=self._watch, daemon=True)

    def _watch(self) -> None:
        if not self.done.wait(self.after):
            self.rescued = True
            os.close(os.open(self.fifo, os.O_WRONLY))

    def __enter__(self) -> _Rescuer:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.done.set()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_a_fifo_or_a_folder_in_any_input_slot_is_refused_without_reading(inputs, tmp_path, capsys) -> None:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    folder = tmp_path / "folder"
    folder.mkdir()
    for bad, said in ((fifo, "not a regular file"), (folder, "a directory")):
        for argv in _slots(inputs, str(bad), tmp_path):
            with _Rescuer(fifo) as rescuer:
                code, err = run(capsys, *argv)
            assert not rescuer.rescued, f"{argv} blocked on the FIFO"
            refused(code, err, said)
    assert peek_input(fifo) == b"" and peek_input(folder) == b"" and peek_input(tmp_path / "missing") == b""


def test_an_unreadable_input_is_a_located_refusal(inputs, tmp_path, monkeypatch, capsys) -> None:
    """``os.open`` refused (what a file without read permission gives a user who is not root)."""
    real = os.open
    victim = str(tmp_path / "secret.csv")
    shutil.copy(inputs / "run.csv", victim)

    def deny(path, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        if str(path) == victim:
            raise PermissionError(13, "Permission denied")
        return real(path, *a, **k)

    monkeypatch.setattr(os, "open", deny)
    with pytest.raises(FileFormatError, match="secret.csv: cannot read: Permission denied"):
        read_input_bytes(victim)
    for argv in (["identify", victim], ["compensate", victim, "--params", str(inputs / "params.json"), "--out",
                                        str(tmp_path / "o.mpf")], ["history", "add", victim, "--db",
                                                                   str(tmp_path / "h.db"), "--machine-id", "M"]):
        refused(*run(capsys, *argv), "Permission denied")


def _unprivileged() -> list[str] | None:
    """A prefix that runs a command as a user without root's rights, [] when we are one, None when impossible."""
    if os.geteuid() != 0:
        return []
    tool = shutil.which("setpriv")
    return [tool, "--reuid=65534", "--regid=65534", "--clear-groups"] if tool else None


AS_PIGE = """
import contextlib, io, json, sys, traceback
from pige_sym.cli.main import main
results = []
for argv in json.loads(sys.argv[1]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except BaseException:  # a crash, as `python -m pige_sym` would show it
            traceback.print_exc()
            code = None
    results.append([code, err.getvalue()])
print(json.dumps(results))
"""
"""Runs each command of the JSON list in ``sys.argv[1]`` as ``pige`` would (``pige_sym.cli.main``); prints, as
its last line, the JSON list of ``[exit status, standard error]`` per command."""


def test_read_only_output_folders_and_unreadable_inputs_for_a_real_user(inputs) -> None:
    prefix = _unprivileged()
    if prefix is None:
        pytest.skip("running as root without setpriv: permissions cannot be tested")
    base = Path(tempfile.mkdtemp())
    try:
        os.chmod(base, 0o777)
        for name in ("run.csv", "prog.mpf", "params.json"):
            shutil.copy(inputs / name, base / name)
            os.chmod(base / name, 0o644)
        (base / "ro").mkdir()
        os.chmod(base / "ro", 0o555)
        shutil.copy(inputs / "prog.mpf", base / "unreadable.mpf")
        os.chmod(base / "unreadable.mpf", 0)
        cases = [(["report", "run.csv", "--out", "ro/rep"], "not writable"),
                 (["compensate", "prog.mpf", "--params", "params.json", "--out", "ro/o.mpf"], "not writable"),
                 (["simulate", "--out", "ro/sub/x.csv"], "not writable"),
                 (["compensate", "unreadable.mpf", "--params", "params.json", "--out", "o.mpf"], "Permission denied")]
        env = os.environ | {"PYTHONPATH": str(Path(__file__).parents[1])}
        # one unprivileged process runs the commands one after the other (`pige`'s imports paid once, not per case)
        proc = subprocess.run([*prefix, sys.executable, "-c", AS_PIGE, json.dumps([argv for argv, _ in cases])],
                              capture_output=True, text=True, timeout=240, cwd=base, env=env)
        assert proc.returncode == 0, proc.stderr
        results = json.loads(proc.stdout.splitlines()[-1])
        assert len(results) == len(cases)
        for (argv, said), (code, err) in zip(cases, results, strict=True):
            assert code == 2 and said in err and "Traceback" not in err, (argv, err)
        assert list((base / "ro").iterdir()) == []
    finally:
        os.chmod(base / "ro", 0o755)
        shutil.rmtree(base)


# ---------------------------------------------------------------------------------------------- report folder


def test_report_replaces_an_earlier_report_only_with_force(inputs, tmp_path, capsys, monkeypatch) -> None:
    out = tmp_path / "rep"
    with monkeypatch.context() as earlier:  # the earlier report's page only; the one that replaces it is drawn
        figures_not_drawn(earlier)  # (figures drawn and checked in test_report.py)
        assert main(["report", str(inputs / "run.csv"), "--out", str(out)]) == 0
    first = (out / "report.html").read_bytes()
    (out / "notes.txt").write_text("mine")
    (out / "report.html").write_text("an earlier report")
    refused(*run(capsys, "report", str(inputs / "run.csv"), "--out", str(out)), "already holds report.html",
            "--force")
    assert (out / "report.html").read_text() == "an earlier report"
    assert main(["report", str(inputs / "run.csv"), "--out", str(out), "--force"]) == 0
    assert (out / "report.html").read_bytes()[:200] == first[:200]
    assert (out / "notes.txt").read_text() == "mine"  # what pige did not write stays
    assert not [p for p in out.iterdir() if "pige-partial" in p.name]
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("x")
    refused(*run(capsys, "report", str(inputs / "run.csv"), "--out", str(not_a_folder)), "is not a folder")


def test_an_error_while_writing_the_folder_leaves_nothing(tmp_path) -> None:
    out = tmp_path / "new"
    with pytest.raises(KeyboardInterrupt), staged_folder(out) as stage:
        (stage / "half.png").write_bytes(b"\x89PNG\r\n")
        raise KeyboardInterrupt
    assert not out.exists() and list(tmp_path.iterdir()) == []
    out.mkdir()
    (out / "report.html").write_text("old")
    with pytest.raises(RuntimeError), staged_folder(out, force=True) as stage:
        (stage / "report.html").write_text("new, but half")
        raise RuntimeError("drawing failed")
    assert [p.name for p in out.iterdir()] == ["report.html"] and (out / "report.html").read_text() == "old"


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_while_the_report_is_written_leaves_nothing_partial(inputs, tmp_path, sig) -> None:
    """The signal is sent once the staged folder exists (the figures are being drawn): the run ends with status
    130, no folder, no hidden leftovers, no traceback."""
    out = tmp_path / "rep"
    cmd = [sys.executable, "-m", "pige_sym", "report", str(inputs / "run.csv"), "--out", str(out)]
    proc = subprocess.Popen(as_from_a_terminal(cmd),  # SIGINT not ignored even under a runner started in background
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not any("pige-partial" in p.name for p in tmp_path.iterdir()) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    leftovers = [p.name for p in tmp_path.iterdir() if "pige-partial" in p.name]
    assert not leftovers and "Traceback" not in err, err
    if out.exists():  # the signal came after the last rename: the report is whole
        assert (out / "report.html").is_file()
        assert all(p.read_bytes().endswith(PNG_END) for p in out.rglob("*.png"))
    else:
        assert proc.returncode == 130 and "interrupted" in err, (proc.returncode, err)


# ----------------------------------------------------------------------- issue 43: links, interrupts, temporary files


@pytest.fixture
def default_sigint():
    """SIGINT raises KeyboardInterrupt in this test, as in a terminal (a test runner may have set another handler)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symbolic links")
def test_a_dangling_link_as_an_output_folder_is_refused_and_never_followed(inputs, tmp_path, capsys) -> None:
    """Issue 43, 7: gen --out, gen --target linuxcnc --out, diagnose --plots (and report, demo) ended in
    FileExistsError; now one line naming the link and its target, and the target is never created."""
    target = tmp_path / "nowhere"
    link = tmp_path / "link"
    link.symlink_to(target)
    ac = "wC'A'bXYZ(C1)t"
    for argv in (["gen", ac, "--out", str(link)], ["gen", "--target", "linuxcnc", ac, "--out", str(link)],
                 ["gen", "--target", "linuxcnc", ac, "--out", str(link / "sub")],
                 ["diagnose", str(inputs / "run.csv"), "--plots", str(link)],
                 ["report", str(inputs / "run.csv"), "--out", str(link), "--no-figures"],
                 ["demo", "--out", str(link / "demo")]):
        refused(*run(capsys, *argv), f"{link} is a symbolic link to {target}, which does not exist")
        assert link.is_symlink() and not target.exists(), argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link"]


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_an_interrupt_as_the_temporary_file_is_made_leaves_none(tmp_path, monkeypatch, default_sigint) -> None:
    """Issue 43, 12: SIGINT right after the temporary file was created, before the writer held its name, left a
    0-byte ``.NAME.*.tmp``; the interrupt now waits until the clean-up knows the file."""
    import tempfile

    from pige_sym.files import atomic_write_text

    real = tempfile.mkstemp

    def made_then_interrupted(*args: object, **kwargs: object) -> tuple[int, str]:
        made = real(*args, **kwargs)  # type: ignore[call-overload]
        os.kill(os.getpid(), signal.SIGINT)  # the handler runs before this function returns
        time.sleep(0.01)
        return made

    monkeypatch.setattr(tempfile, "mkstemp", made_then_interrupted)
    with pytest.raises(KeyboardInterrupt):
        atomic_write_text(tmp_path / "pige_xyzac_trt.comp", "component pige_xyzac_trt;\n")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_an_interrupt_lost_in_a_finaliser_still_ends_the_report_with_130(inputs, tmp_path, monkeypatch, capsys,
                                                                        default_sigint) -> None:
    """Issue 43, 11: Python drops a KeyboardInterrupt raised in a finaliser ("Exception ignored ... KeyboardInterrupt")
    and goes on: the report was written and the run ended with status 0.  Now status 130 and no report."""
    import pige_sym.report.html as html

    lost: list[BaseException | None] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: lost.append(u.exc_value))

    class Finaliser:
        def __del__(self) -> None:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.01)

    real = html.render_html

    def render_and_lose_an_interrupt(*args: object, **kwargs: object) -> str:
        text = real(*args, **kwargs)  # type: ignore[arg-type]
        Finaliser()  # dropped at once: the SIGINT lands in its __del__
        return text

    monkeypatch.setattr(html, "render_html", render_and_lose_an_interrupt)
    figures_not_drawn(monkeypatch)  # the interrupt comes after the figures, into the page: they are not drawn
    out = tmp_path / "rep"
    code, err = run(capsys, "report", str(inputs / "run.csv"), "--out", str(out), "--no-figures")
    assert [type(e) for e in lost] == [KeyboardInterrupt]  # the interrupt was indeed swallowed on its way
    assert code == 130 and err.strip().endswith("interrupted"), (code, err)
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == []


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_an_interrupt_while_the_commands_are_loaded_ends_with_130(monkeypatch, capsys, default_sigint) -> None:
    """Building the parser imports every command's module (seconds on a loaded machine): Ctrl-C there gave a
    traceback, or NumPy's "PyCapsule_Import could not import module" and status 1."""
    import importlib

    cli = importlib.import_module("pige_sym.cli.main")  # the module (pige_sym.cli.main is also the function)

    def import_broken_by_the_interrupt(command: str | None = None) -> None:
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.01)
        except KeyboardInterrupt:  # what NumPy's C import does with it
            raise ImportError('PyCapsule_Import could not import module "datetime"') from None

    monkeypatch.setattr(cli, "build_parser", import_broken_by_the_interrupt)
    assert cli.main(["gen", "--target", "linuxcnc", "wC'A'bXYZ(C1)t"]) == 130
    assert capsys.readouterr().err == "pige gen: interrupted\n"


# ------------------------------------------------------------------------- issue 43, 6: a damaged history database


def _history(folder: Path, inputs: Path, db: str) -> None:
    """Two runs of machine M in ``db`` (the second a simulation with another seed)."""
    second = folder / "run2.csv"
    if not second.exists():
        assert main(["simulate", "--out", str(second), "--seed", "2", "--points", "12"]) == 0
    for f in (inputs / "run.csv", second):
        assert main(["history", "add", str(f), "--machine-id", "M", "--db", db, "--method", "gauss-newton"]) == 0


def _last_pages(path: Path) -> None:
    import random

    size = path.stat().st_size
    with open(path, "r+b") as fh:
        fh.seek(size - 8192)
        fh.write(random.Random(43).randbytes(8192))


DAMAGES = {  # what damages the file, what the refusal says is damaged
    "random bytes in the last pages": (_last_pages, "is damaged ("),
    "runs dropped": ("DROP TABLE runs", "is damaged (the table runs is missing)"),
    "values_json": ("UPDATE runs SET values_json = '[1.5, 2,' WHERE id = 1",
                    "is damaged (run 1, values_json: not valid JSON"),
    "covariance size": ("UPDATE runs SET covariance_json = '[[1, 0], [0, 1]]' WHERE id = 2",
                        "is damaged (run 2, covariance_json: expected a 8 x 8 matrix"),
    "dof": ("UPDATE runs SET dof = 'abc' WHERE id = 1",
            "is damaged (run 1, dof: expected a whole number >= 0, got the text 'abc')"),
}


@pytest.fixture(scope="module")
def history_file(inputs, tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("history")
    _history(d, inputs, str(d / "h.sqlite"))
    return d / "h.sqlite"


@pytest.mark.parametrize("damage", sorted(DAMAGES))
def test_a_damaged_history_is_refused_in_one_line_and_left_as_it_was(inputs, history_file, tmp_path, capsys,
                                                                     damage) -> None:
    """Issue 43, 6: ``history show`` ended in a traceback.  Now every command that opens the history (show, add,
    report --history) refuses in one line naming the file, what is damaged and how to recover, and the file's
    bytes stay as they were (reading opens it read-only; nothing is migrated into a damaged file)."""
    import sqlite3

    db = tmp_path / "h.sqlite"
    shutil.copy(history_file, db)
    how, said = DAMAGES[damage]
    if callable(how):
        how(db)
    else:
        with sqlite3.connect(db) as conn:
            conn.execute(how)
        conn.close()
    before = db.read_bytes()
    said_by_show = None
    for argv in (["history", "show", "M", "--db", str(db)], ["history", "show", "M", "--db", str(db), "--json"],
                 ["history", "add", str(inputs / "run.csv"), "--machine-id", "N", "--db", str(db)],
                 ["report", str(inputs / "run.csv"), "--history", "M", "--db", str(db), "--out", str(tmp_path / "r"),
                  "--no-figures"],
                 # the check-up's commands (issue 42): pige checkup reads the file with sqlite3, the same checks
                 ["checkup", str(inputs / "run.csv"), "--machine-id", "M", "--db", str(db)],
                 ["history", "fleet", "--db", str(db)], ["plan", "--checkup", "--machine-id", "M", "--db", str(db)],
                 ["program", "--checkup", "--machine-id", "M", "--db", str(db), "--dialect", "linuxcnc", "--out",
                  str(tmp_path / "c.ngc")]):
        code, err = run(capsys, *argv)
        refused(code, err, f"history database {db} {said}", "restore the file from a backup",
                "pige has changed nothing in it")
        said_by_show = said_by_show or err.split(": ", 1)[1]
        assert err.split(": ", 1)[1] == said_by_show, argv  # every command, the same words
        assert db.read_bytes() == before, argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.sqlite"]  # no journal, no report, no program


def test_a_damaged_postgresql_history_is_refused_by_the_same_reader(inputs, tmp_path, capsys, request) -> None:
    """The same checks on PostgreSQL (no page check there: the server keeps its pages); the rows are unchanged."""
    import sqlalchemy as sa

    url = request.getfixturevalue("postgres_url")  # skips when no server can start

    engine = sa.create_engine(url.replace("postgresql://", "postgresql+psycopg://"))
    cases = {k: v for k, v in DAMAGES.items() if not callable(v[0])}
    cases["dof"] = ("ALTER TABLE runs ALTER COLUMN dof TYPE text; UPDATE runs SET dof = 'abc'",
                    DAMAGES["dof"][1])
    for damage, (how, said) in cases.items():
        with engine.begin() as conn:
            for table in ("runs", "machines", "schema_version"):
                conn.execute(sa.text(f"DROP TABLE IF EXISTS {table} CASCADE"))
        _history(tmp_path, inputs, url)
        with engine.begin() as conn:
            for statement in how.split(";"):
                conn.execute(sa.text(statement))

        def dump() -> list[object]:
            with engine.connect() as conn:
                names = sorted(sa.inspect(conn).get_table_names())
                return [(t, sorted(map(tuple, conn.execute(sa.text(f"SELECT * FROM {t}")).all()), key=repr))
                        for t in names]

        before = dump()
        for argv in (["history", "show", "M", "--db", url],
                     ["history", "add", str(inputs / "run.csv"), "--machine-id", "N", "--db", url],
                     ["checkup", str(inputs / "run.csv"), "--machine-id", "M", "--db", url]):
            code, err = run(capsys, *argv)
            refused(code, err, said, "restore the database from a backup")
            assert dump() == before, (damage, argv)
    engine.dispose()


@pytest.mark.parametrize("umask, mode", [(0o002, 0o664), (0o022, 0o644), (0o077, 0o600)])
def test_a_new_history_file_gets_the_mode_of_every_pige_output(inputs, tmp_path, umask, mode) -> None:
    """Not a defect in issue 43, decided: SQLite made the file 0644 whatever the umask (0664 was asked for under
    umask 002, so a shop's group could add runs); it is now created as every pige output is, 0666 less the umask."""
    db = tmp_path / "sub" / "h.sqlite"
    old = os.umask(umask)
    try:
        assert main(["history", "add", str(inputs / "run.csv"), "--machine-id", "M", "--db", str(db), "--method",
                     "gauss-newton"]) == 0
    finally:
        os.umask(old)
    assert db.stat().st_mode & 0o777 == mode
