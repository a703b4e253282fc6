"""`pipeline report` as a user meets it: errors, --skip-bad, and never losing old reports."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.errors import ReportError
from pipeline.report import rerun_rrd
from pipeline.stages import report as report_stage
from pipeline.stages import report_commit
from tests.analysis.bagfactory import damage, paper_like, write_bag

KINDS = ("truncated", "bitflip", "empty", "not_mcap", "no_joint_states", "no_stamp")
# A /joint_states schema without a header: legal MCAP, but no time stamps to read.
NO_STAMP_JOINT_STATE = "string[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"


def _good(root: Path) -> None:
    write_bag(root, paper_like("pid_ok", "pid", duration_s=1.5, motion_end_s=1.0))
    write_bag(root, paper_like("ctc_ok", "ctc", duration_s=1.5, motion_end_s=1.0))


def _bad(root: Path, kind: str) -> Path:
    ep = paper_like(f"bad_{kind}", "pid", duration_s=0.5, scenario="broken")
    if kind == "no_joint_states":
        return write_bag(root, ep, topics=("/controller_state", "/planned_trajectory"))
    if kind == "no_stamp":
        ep.joint_state_msgdef = ("sensor_msgs/msg/JointState", NO_STAMP_JOINT_STATE)
        return write_bag(root, ep)
    path = write_bag(root, ep)
    damage(path, kind)
    return path


def _old_reports(root: Path) -> dict[str, bytes]:
    out = root / "reports"
    (out / "figures").mkdir(parents=True)
    (out / "report.md").write_text("earlier report\n")
    (out / "metrics.json").write_text('{"earlier": true}\n')
    (out / "figures" / "old.png").write_bytes(b"png")
    # what an earlier `pipeline report` lists as its own (it may remove these, nothing else)
    (out / report_commit.MANIFEST).write_text("report.md\nmetrics.json\nfigures/old.png\n")
    return _snapshot(out)


def _snapshot(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


def _run(monkeypatch: pytest.MonkeyPatch, root: Path, *args: str) -> int:
    monkeypatch.chdir(root)
    monkeypatch.setattr(sys, "argv", ["pipeline", "report", *args])
    with pytest.raises(SystemExit) as info:
        main()
    code = info.value.code
    return int(code) if code is not None else 0


@pytest.mark.parametrize("kind", KINDS)
def test_bad_recording_fails_with_one_line_and_keeps_old_reports(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], kind: str
) -> None:
    _good(tmp_path / "recordings")
    bad = _bad(tmp_path / "recordings", kind)
    before = _old_reports(tmp_path)
    assert _run(monkeypatch, tmp_path) == 1
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "Traceback" not in err
    assert bad.name in errors[0] and "--skip-bad" in errors[0]
    assert _snapshot(tmp_path / "reports") == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.slow
def test_skip_bad_reports_the_rest_and_lists_what_was_skipped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _good(tmp_path / "recordings")
    bad = [_bad(tmp_path / "recordings", kind) for kind in KINDS]
    _old_reports(tmp_path)
    assert _run(monkeypatch, tmp_path, "--skip-bad") == 0
    out = capsys.readouterr()
    text = (tmp_path / "reports" / "report.md").read_text(encoding="utf-8")
    doc = json.loads((tmp_path / "reports" / "metrics.json").read_text(encoding="utf-8"))
    assert set(doc["episodes"]) == {"pid_ok", "ctc_ok"}
    assert len(doc["skipped"]) == len(KINDS)
    for path in bad:
        assert path.name in text
        assert path.name in out.err
    # The stale figure of the earlier report is gone.
    assert not (tmp_path / "reports" / "figures" / "old.png").exists()
    # Each skipped recording is one line naming its file once.
    skipped = [line for line in out.err.splitlines() if line.startswith("skipped: ")]
    assert len(skipped) == len(KINDS)
    for line in skipped:
        name = next(p for p in bad if p.name in line).name
        assert line.count(f"recordings/{name}") == 1, line


def test_two_recordings_of_one_episode_name_are_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _good(tmp_path / "recordings" / "a")
    _good(tmp_path / "recordings" / "b")
    assert _run(monkeypatch, tmp_path) == 1
    err = capsys.readouterr().err
    assert "episode 'ctc_ok' is recorded twice" in err and "recordings/b/ctc_ok" in err


def test_no_recordings_says_to_run_record_first(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "recordings").mkdir()
    assert _run(monkeypatch, tmp_path) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: no recordings found in recordings")
    assert "pipeline record" in err


def test_unknown_baseline_lists_controllers_present(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _good(tmp_path / "recordings")
    assert _run(monkeypatch, tmp_path, "--baseline", "lqr") == 1
    err = capsys.readouterr().err.strip()
    assert err == (
        "error: unknown baseline controller 'lqr'; valid: ctc, pid "
        "(the controllers in the recordings; choose one with --baseline)"
    )
    assert not (tmp_path / "reports").exists()


def test_a_baseline_naming_no_recorded_controller_is_refused_with_one_controller(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    write_bag(tmp_path / "recordings", paper_like("ctc_ok", "ctc", duration_s=1.5))
    assert _run(monkeypatch, tmp_path, "--baseline", "nope") == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("error: --baseline 'nope': no such controller in the recordings")
    assert not (tmp_path / "reports").exists()
    # the default baseline with one other controller: nothing to compare, no error
    assert _run(monkeypatch, tmp_path) == 0


def test_failure_while_writing_leaves_earlier_reports_and_no_temporary_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _good(tmp_path / "recordings")
    before = _old_reports(tmp_path)

    def broken_rrd(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(rerun_rrd, "write_rrd", broken_rrd)  # loaded when a report is written
    with pytest.raises(ReportError, match=r"disk full.*earlier reports are untouched"):
        report_stage.run_report(
            recordings_dir=tmp_path / "recordings", out_dir=tmp_path / "reports"
        )
    assert _snapshot(tmp_path / "reports") == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recordings", "reports"]


@pytest.mark.slow
def test_cli_process_prints_one_error_line_without_traceback(tmp_path: Path) -> None:
    recordings = tmp_path / "recordings"
    _bad(recordings, "truncated")
    proc = subprocess.run(
        [sys.executable, "-c", "from pipeline.cli import main; main()", "report"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 1
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: ")
    assert "truncated" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "reports").exists()


@pytest.mark.slow
def test_successful_run_prints_a_summary_table(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _good(tmp_path / "recordings")
    assert _run(monkeypatch, tmp_path) == 0
    out = capsys.readouterr().out
    assert "pid_ok" in out and "ctc_ok" in out and "wrote" in out
    for name in ("report.md", "metrics.json", "recording.rrd", "plots/errors.csv"):
        assert (tmp_path / "reports" / name).is_file()


# --- replacing outputs in place --------------------------------------------------------------


def _tracked_extras(out: Path) -> dict[str, bytes]:
    """Files a user or git keeps in the reports folder; the report must leave them alone."""
    extras = {
        "plots/.gitignore": b"/errors.csv\n/velocities.csv\n",
        "figures/.gitignore": b"*.png\n",
        ".hidden": b"keep\n",
        "figures/README.txt": b"figures are generated\n",
        "notes.md": b"my notes\n",
    }
    for rel, data in extras.items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_bytes(data)
    return extras


def test_report_keeps_files_it_does_not_produce_and_removes_stale_figures(
    tmp_path: Path,
) -> None:
    _good(tmp_path / "recordings")
    _old_reports(tmp_path)
    out = tmp_path / "reports"
    extras = _tracked_extras(out)
    result = report_stage.run_report(recordings_dir=tmp_path / "recordings", out_dir=out)
    for rel, data in extras.items():
        assert (out / rel).read_bytes() == data, rel
    assert not (out / "figures" / "old.png").exists()
    pngs = sorted(f"figures/{p.name}" for p in (out / "figures").glob("*.png"))
    assert pngs == sorted(f for f in result.files if f.endswith(".png"))
    assert (out / "report.md").read_text(encoding="utf-8").startswith("# Tracking report")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_failure_while_swapping_outputs_in_leaves_the_earlier_report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _good(tmp_path / "recordings")
    _old_reports(tmp_path)
    out = tmp_path / "reports"
    _tracked_extras(out)
    before = _snapshot(out)

    def full_disk(a: Path, b: Path) -> bool:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(report_commit, "exchange", full_disk)
    with pytest.raises(ReportError, match="earlier reports are untouched"):
        report_stage.run_report(recordings_dir=tmp_path / "recordings", out_dir=out)
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recordings", "reports"]


def test_report_removes_only_files_its_manifest_lists(tmp_path: Path) -> None:
    """A figure the user put in figures/ survives; one the last report wrote and this one
    does not write again is removed; a folder without a manifest loses nothing."""
    _good(tmp_path / "recordings")
    out = tmp_path / "reports"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "mine.png").write_bytes(b"user's own")
    (out / "campaigns").mkdir()
    (out / "campaigns" / "mine.csv").write_bytes(b"a,b\n")
    report_stage.run_report(recordings_dir=tmp_path / "recordings", out_dir=out)
    assert (out / "figures" / "mine.png").read_bytes() == b"user's own"
    assert (out / "campaigns" / "mine.csv").read_bytes() == b"a,b\n"
    listed = (out / report_commit.MANIFEST).read_text().splitlines()
    assert "report.md" in listed and "figures/mine.png" not in listed
    (out / "figures" / "gone.png").write_bytes(b"x")
    (out / report_commit.MANIFEST).write_text("\n".join([*listed, "figures/gone.png"]) + "\n")
    report_stage.run_report(recordings_dir=tmp_path / "recordings", out_dir=out)
    assert not (out / "figures" / "gone.png").exists()
    assert (out / "figures" / "mine.png").read_bytes() == b"user's own"


@pytest.mark.parametrize("out", ["", ".", "..", "{cwd}"])
def test_out_naming_the_working_folder_is_refused_and_nothing_deleted(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], out: str
) -> None:
    work = tmp_path / "work"
    _good(work / "recordings")
    (work / "figures").mkdir()
    (work / "figures" / "mine.png").write_bytes(b"png")
    (work / "campaigns").mkdir()
    (work / "campaigns" / "mine.csv").write_bytes(b"a\n")
    before = _snapshot(tmp_path)
    out = out.replace("{cwd}", str(work))
    monkeypatch.chdir(work)
    monkeypatch.setattr(sys, "argv", ["pipeline", "report", "--out", out])
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert "--out" in err
    assert _snapshot(tmp_path) == before
    assert sorted(p.name for p in work.iterdir()) == ["campaigns", "figures", "recordings"]


# --- the command line at 80 columns ------------------------------------------------------------


def test_summary_fits_80_columns_without_cutting_names_or_numbers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from rich.console import Console

    import pipeline.cli.report_cmd as cli

    long_names = ("mismatch-payload-pd_gravity-seed-12", "mismatch-payload-pid-seed-12")
    for name, ctrl in zip(long_names, ("pd_gravity", "pid"), strict=True):
        ep = paper_like(name, ctrl, duration_s=0.6, motion_end_s=0.4, scenario="mismatch-payload")
        write_bag(tmp_path / "recordings", ep)
    bad = _bad(tmp_path / "recordings", "truncated")
    monkeypatch.setattr(cli, "console", Console(width=80, force_terminal=False))
    assert _run(monkeypatch, tmp_path, "--skip-bad") == 0
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert all(len(line) <= 80 for line in lines)
    assert "…" not in out
    assert "[rad]" in out  # the unit, not eaten as markup
    header = next(line for line in lines if "controller" in line)
    first_column = "".join(line[: header.index("controller")].strip() for line in lines)
    for name in long_names:
        assert name in first_column  # folded onto the next line, never cut
    numbers = re.findall(r"\d\.\d{3}e-\d\d", out)
    assert len(numbers) == 6
    (skipped,) = [line for line in err.splitlines() if line.startswith("skipped: ")]
    assert skipped.count(f"recordings/{bad.name}") == 1


def test_reader_warnings_are_printed_on_stderr(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _good(tmp_path / "recordings")
    ep = paper_like("odd_settings", "pid", duration_s=0.6, motion_end_s=0.4, scenario="odd")
    ep.raw_settings = "{not json"
    write_bag(tmp_path / "recordings", ep)
    assert _run(monkeypatch, tmp_path) == 0
    err = capsys.readouterr().err
    (line,) = [x for x in err.splitlines() if x.startswith("warning: ")]
    assert line.startswith("warning: odd_settings: ") and "not valid JSON" in line


def test_reports_through_a_symlinked_out_take_the_target_s_lock(tmp_path: Path) -> None:
    """A run holding the lock of reports/ makes a second one through a symlink to it refuse
    (the lock is taken on the resolved path); the symlink stays a symlink after a run."""
    from pipeline.fsutil import OutputLock

    _good(tmp_path / "recordings")
    real = tmp_path / "reports"
    real.mkdir()
    (tmp_path / "link").symlink_to(real, target_is_directory=True)
    with OutputLock(real, command="`pipeline report`"):
        done = subprocess.run(
            [sys.executable, "-m", "pipeline", "report", "--out", "link"],
            cwd=tmp_path, capture_output=True, text=True, timeout=300,
            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])},
        )  # fmt: skip
    assert done.returncode == 1
    assert "another `pipeline report`" in done.stderr and f"pid {os.getpid()}" in done.stderr
    assert list(real.iterdir()) == []
    report_stage.run_report(recordings_dir=tmp_path / "recordings", out_dir=tmp_path / "link")
    assert (tmp_path / "link").is_symlink() and (real / "report.md").is_file()
