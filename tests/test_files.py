"""Files are never clobbered: outputs need --force, never replace an input or a non-regular file, and are
checked before any long work (acquire: before the port is even opened)."""

from __future__ import annotations

import json
import os
import stat

import pytest

from pige_sym.cli.main import main
from pige_sym.errors import InputError
from pige_sym.files import atomic_write_text, check_output

NO_PORT = "/dev/does-not-exist-pige"  # reaching the port means the file checks passed


def _err_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_check_output_refuses_every_way_of_clobbering(tmp_path) -> None:
    src = tmp_path / "in.csv"
    src.write_text("x")
    with pytest.raises(InputError, match="exists: pass --force"):
        check_output(src)
    assert check_output(src, force=True) == src
    with pytest.raises(InputError, match="also an input"):
        check_output(src, force=True, inputs=[src])
    link = tmp_path / "link.csv"
    link.symlink_to(src)
    with pytest.raises(InputError, match="also an input"):
        check_output(link, force=True, inputs=[src])
    with pytest.raises(InputError, match="symbolic link"):
        check_output(link, force=True)
    hard = tmp_path / "hard.csv"
    os.link(src, hard)
    with pytest.raises(InputError, match="also an input"):
        check_output(hard, force=True, inputs=[src])
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="not a regular file"):
        check_output(fifo, force=True)
    with pytest.raises(InputError, match="is a directory"):
        check_output(tmp_path, force=True)
    with pytest.raises(InputError, match="not a directory"):
        check_output(src / "below.csv")


def test_atomic_write_never_replaces_a_link_or_fifo_and_leaves_no_temp_file(tmp_path) -> None:
    target = tmp_path / "t.txt"
    atomic_write_text(target, "one\n")
    atomic_write_text(target, "two\n")
    assert target.read_text() == "two\n"
    link = tmp_path / "l.txt"
    link.symlink_to(target)
    fifo = tmp_path / "f"
    os.mkfifo(fifo)
    for bad in (link, fifo):
        with pytest.raises(InputError, match="not a regular file"):
            atomic_write_text(bad, "three\n")
    assert target.read_text() == "two\n" and stat.S_ISFIFO(fifo.stat().st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f", "l.txt", "t.txt"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder_is_refused_before_work(tmp_path, capsys) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        assert main(["acquire", "--port", NO_PORT, "--out", str(ro / "a.csv"), "--no-progress"]) == 2
        assert "not writable" in _err_line(capsys)
        assert main(["simulate", "--out", str(ro / "s.csv")]) == 2
        assert "not writable" in _err_line(capsys)
    finally:
        ro.chmod(0o700)


def _acquire(*extra: str) -> list[str]:
    return ["acquire", "--port", NO_PORT, "--no-progress", *extra]


def test_acquire_refuses_outputs_before_opening_the_port(tmp_path, capsys) -> None:
    done = tmp_path / "done.csv"
    done.write_text("# pige-rtest 1\n# machine: wC'A'bXYZ(C1)t\n")
    log = tmp_path / "done.raw.log"
    log.write_bytes(b"old bytes")
    before = done.read_bytes()
    assert main(_acquire("--out", str(done))) == 2
    assert "exists: pass --force" in _err_line(capsys)
    # --resume or --force get past the file checks (and stop at the missing port)
    assert main(_acquire("--out", str(done), "--force")) == 2
    assert "cannot open port" in _err_line(capsys)
    assert done.read_bytes() == before and log.read_bytes() == b"old bytes"  # nothing replaced before a row
    new = tmp_path / "new.csv"
    assert main(_acquire("--out", str(new), "--raw-log", str(new))) == 2
    assert "same file as --out" in _err_line(capsys)
    prog = tmp_path / "angles.csv"
    prog.write_text("A_deg,C_deg\n0,0\n10,20\n")
    assert main(_acquire("--program", str(prog), "--out", str(prog), "--force")) == 2
    assert "also an input" in _err_line(capsys)
    assert prog.read_text() == "A_deg,C_deg\n0,0\n10,20\n"
    assert main(_acquire("--program", str(prog), "--out", str(new), "--raw-log", str(prog))) == 2
    assert "also an input" in _err_line(capsys)
    assert main(_acquire("--out", str(tmp_path))) == 2
    assert "is a directory" in _err_line(capsys)
    other = tmp_path / "notes.txt"
    other.write_text("my notes")
    assert main(_acquire("--out", str(other), "--force")) == 2
    assert "not a pige-rtest file" in _err_line(capsys) and other.read_text() == "my notes"
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    assert main(_acquire("--out", str(fifo), "--force")) == 2
    assert "not a regular file" in _err_line(capsys)


def test_simulate_needs_force_and_never_writes_over_its_input(tmp_path, capsys) -> None:
    out = tmp_path / "s.csv"
    assert main(["simulate", "--out", str(out), "--seed", "1", "--points", "6"]) == 0
    capsys.readouterr()
    first = out.read_bytes()
    assert main(["simulate", "--out", str(out), "--seed", "2", "--points", "6"]) == 2
    assert "exists: pass --force" in _err_line(capsys) and out.read_bytes() == first
    assert main(["simulate", "--out", str(out), "--seed", "2", "--points", "6", "--force"]) == 0
    assert out.read_bytes() != first
    capsys.readouterr()
    angles = tmp_path / "angles.csv"
    angles.write_text("A_deg,C_deg\n0,0\n10,20\n20,40\n")
    assert main(["simulate", "--trajectory", str(angles), "--out", str(angles), "--force"]) == 2
    assert "also an input" in _err_line(capsys)
    truth = tmp_path / "angles.truth.json"
    assert not truth.exists()


def test_gen_regenerates_kernels_but_never_replaces_a_foreign_file(tmp_path, capsys) -> None:
    from pige_sym.cli.gen import GENERATED_MARK, _refuse_foreign
    from pige_sym.codegen.machine_code import parse_machine_code

    code = "wC'A'bXYZ(C1)t"
    kernel = tmp_path / f"{parse_machine_code(code).module_name}.py"
    kernel.write_text(GENERATED_MARK + " " + code + "\n")
    _refuse_foreign(kernel, force=False)  # a generated kernel is regenerated freely
    kernel.write_text("my own module\n")
    assert main(["gen", code, "--out", str(tmp_path)]) == 2  # refused before any SymPy work
    assert "exists: pass --force" in _err_line(capsys) and kernel.read_text() == "my own module\n"
    assert main(["gen", code, "--out", str(kernel)]) == 2
    assert "is not a directory" in _err_line(capsys)


def test_diagnose_refuses_to_replace_plots_before_the_long_work(tmp_path, capsys) -> None:
    csv = tmp_path / "s.csv"
    assert main(["simulate", "--out", str(csv), "--seed", "1", "--points", "8"]) == 0
    plots = tmp_path / "plots"
    plots.mkdir()
    (plots / "residual_rows.png").write_bytes(b"my picture")
    capsys.readouterr()
    assert main(["diagnose", str(csv), "--plots", str(plots)]) == 2
    assert "residual_rows.png exists: pass --force" in _err_line(capsys)
    assert (plots / "residual_rows.png").read_bytes() == b"my picture"
    assert main(["diagnose", str(csv), "--plots", str(csv)]) == 2
    assert "is not a directory" in _err_line(capsys)


def test_an_unreadable_acquisition_summary_is_kept_aside_not_dropped(tmp_path) -> None:
    from pige_sym.acquisition.options import AcquisitionSummary
    from pige_sym.acquisition.outputs import _write_summary, summary_path

    out = tmp_path / "run.csv"
    side = summary_path(out)
    side.write_text("{not json")
    _write_summary(AcquisitionSummary(port="p", out=str(out), raw_log=None, program="x", n_poses=3, resumed=True), out)
    assert (tmp_path / "run.acq.json.unreadable").read_text() == "{not json"
    assert len(json.loads(side.read_text())["sessions"]) == 1


@pytest.mark.parametrize(("umask", "mode"), [(0o022, 0o644), (0o027, 0o640), (0o077, 0o600)])
def test_new_files_follow_the_umask_and_replaced_files_keep_their_mode(tmp_path, umask, mode) -> None:
    """A DNC account or a web server must be able to read what pige writes (0644 under umask 022)."""
    import os
    import stat

    from pige_sym.files import atomic_write_text

    old = os.umask(umask)
    try:
        new = atomic_write_text(tmp_path / "new.mpf", "G0 X0\n")
        assert stat.S_IMODE(new.stat().st_mode) == mode
        kept = tmp_path / "kept.mpf"
        kept.write_text("old\n")
        kept.chmod(0o604)
        atomic_write_text(kept, "G0 X1\n")
        assert stat.S_IMODE(kept.stat().st_mode) == 0o604 and kept.read_text() == "G0 X1\n"
        assert main(["simulate", "--seed", "1", "--out", str(tmp_path / "run.csv")]) == 0
        for written in (tmp_path / "run.csv", tmp_path / "run.truth.json"):
            assert stat.S_IMODE(written.stat().st_mode) == mode, written
    finally:
        os.umask(old)
