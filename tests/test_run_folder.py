"""mjx_arm.run_folder: one writer per run folder for every command that writes one, and output
folders checked before any work (issue 32, items 5 and 6). No simulation or training: a second
writer is refused before any, and eval.shapes' own work is replaced by a stand-in."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mjx_arm import run_folder

REPO = Path(__file__).resolve().parent.parent
# The holder loads run_folder.py alone (no jax): it holds the lock within a fraction of a second.
HOLDER = """
import importlib.util, sys, time
spec = importlib.util.spec_from_file_location("run_folder", sys.argv[1])
run_folder = importlib.util.module_from_spec(spec)
spec.loader.exec_module(run_folder)
run_folder.lock_folder(sys.argv[2], beside=sys.argv[3] == "1")
print("held", flush=True)
time.sleep(120)
"""


@contextlib.contextmanager
def held_by_another_process(folder: Path, beside: bool = False):
    """Yields the pid of a live process that holds `folder`'s lock."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, run_folder.__file__, str(folder), "1" if beside else "0"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "held"
        yield proc.pid
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()


def refused(main, argv, capsys) -> str:
    """The usage error (exit status 2) `main(argv)` ends with."""
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    return capsys.readouterr().err


def test_a_second_writer_is_refused_until_the_first_ends_however_it_ends(tmp_path):
    folder = tmp_path / "run"
    for beside in (False, True):
        with held_by_another_process(folder, beside) as pid:
            with pytest.raises(run_folder.FolderBusyError, match=f"in use by process {pid}"):
                run_folder.lock_folder(folder, beside=beside)
        # The holder was killed (SIGKILL): the kernel dropped its lock, its file is reused.
        with run_folder.lock_folder(folder, beside=beside) as lock:
            assert lock.path.read_text() == f"{os.getpid()}\n"
        assert not lock.path.exists()


def test_a_lock_leaves_no_trace_in_a_folder_it_made_and_nothing_was_written_to(tmp_path):
    run_folder.lock_folder(tmp_path / "a" / "b").release()
    assert list(tmp_path.iterdir()) == []
    with run_folder.lock_folder(tmp_path / "kept") as lock:
        (lock.folder / "out.txt").write_text("x")
    assert [p.name for p in (tmp_path / "kept").iterdir()] == ["out.txt"]


def test_one_process_gets_its_own_lock_back(tmp_path):
    """A command's main called twice in one process (as the tests do) is one owner."""
    first = run_folder.lock_folder(tmp_path / "run")
    assert run_folder.lock_folder(tmp_path / "run") is first
    first.release()


def test_a_second_babble_into_one_folder_is_refused_before_any_work(tmp_path, capsys):
    from mjx_arm.babble import cli

    out = tmp_path / "babble"
    argv = ["--n", "1", "--n-val", "1", "--duration", "1", "--backend", "c", "--out", str(out)]
    argv += ["--no-progress"]
    with held_by_another_process(out, beside=True) as pid:
        err = refused(cli.main, argv, capsys)
    assert f"{out} is in use by process {pid}" in err
    assert not out.exists()


def test_a_second_trainer_on_one_workdir_is_refused_before_any_work(tmp_path, capsys):
    from ccgan import train

    workdir = tmp_path / "forward.partial"
    argv = ["--source", "s.npz", "--constrained", "c.npz", "--workdir", str(workdir)]
    with held_by_another_process(workdir, beside=True) as pid:
        err = refused(train.main, argv, capsys)
    assert f"--workdir: {workdir} is in use by process {pid}" in err
    assert not workdir.exists()


def fake_evaluate(figures, videos=()):
    """A stand-in for eval.pipeline.evaluate that writes `figures`, `videos` and a shapes.json
    listing them into the run's folder, as the real one does at its end."""

    def evaluate(cfg, command="", log=print):
        out = Path(cfg.out_dir)
        out.mkdir(parents=True, exist_ok=True)
        for name in (*figures, *videos):
            (out / name).write_text(command)
        results = {"figures": list(figures), "videos": list(videos)}
        (out / "shapes.json").write_text(json.dumps(results))
        (out / "shapes.md").write_text(command)
        return results

    return evaluate


EVAL_ARGV = ["--methods", "none", "--no-robustness", "--quick", "--shapes", "circle"]


def test_a_second_evaluation_into_one_folder_is_refused(tmp_path, capsys, monkeypatch):
    from eval import shapes

    monkeypatch.setattr(shapes, "evaluate", fake_evaluate(["errors.png"]))
    out = tmp_path / "table"
    with held_by_another_process(out, beside=True) as pid:
        err = refused(shapes.main, [*EVAL_ARGV, "--out", str(out)], capsys)
    assert f"{out} is in use by process {pid}" in err
    assert not out.exists()


def test_a_rerun_of_the_evaluation_removes_the_earlier_runs_plots_it_did_not_remake(
    tmp_path, monkeypatch
):
    """The earlier run scored two shapes with videos, the rerun one shape without: the kite's
    plot and both videos go; the resume caches and a user's notes stay."""
    from eval import shapes

    out = tmp_path / "table"
    figures = ["shape_circle.png", "shape_kite.png", "errors.png"]
    monkeypatch.setattr(shapes, "evaluate", fake_evaluate(figures, ["video_circle.mp4"]))
    shapes.main([*EVAL_ARGV, "--out", str(out)])
    (out / "mpc_commands.npz").write_text("cache")
    (out / "notes.txt").write_text("mine")
    monkeypatch.setattr(shapes, "evaluate", fake_evaluate(["shape_circle.png", "errors.png"]))
    shapes.main([*EVAL_ARGV, "--out", str(out)])
    assert sorted(p.name for p in out.iterdir()) == [
        "errors.png",
        "mpc_commands.npz",
        "notes.txt",
        "shape_circle.png",
        "shapes.json",
        "shapes.md",
    ]


def test_an_evaluation_into_a_path_through_a_file_is_a_usage_error(tmp_path, capsys):
    from eval import shapes

    (tmp_path / "file").write_text("x")
    for out in (tmp_path / "file", tmp_path / "file" / "table"):
        err = refused(shapes.main, [*EVAL_ARGV, "--out", str(out)], capsys)
        assert f"--out: {tmp_path / 'file'} exists and is not a folder" in err
    if os.geteuid() == 0:
        return  # root writes into a read-only folder: nothing to refuse
    locked = tmp_path / "read_only"
    locked.mkdir(mode=0o555)
    err = refused(shapes.main, [*EVAL_ARGV, "--out", str(locked / "table")], capsys)
    assert f"cannot write in {locked}" in err


def test_compare_runs_refuses_a_bad_out_and_a_manifest_without_files(tmp_path, capsys):
    from experiments import compare_runs

    for run in ("a", "b"):
        (tmp_path / run / "ccgan").mkdir(parents=True)
        (tmp_path / run / "ccgan" / "stage.json").write_text(json.dumps({"files": {"x": "1"}}))
    runs = [str(tmp_path / "a"), str(tmp_path / "b")]
    (tmp_path / "file").write_text("x")
    err = refused(compare_runs.main, [*runs, "--out", str(tmp_path / "file" / "c.md")], capsys)
    assert "exists and is not a folder" in err
    err = refused(compare_runs.main, [*runs, "--out", str(tmp_path / "a")], capsys)
    assert "is a folder; name a file" in err
    compare_runs.main([*runs, "--out", str(tmp_path / "new" / "c.md")])
    assert (tmp_path / "new" / "c.md").exists()
    capsys.readouterr()
    (tmp_path / "b" / "ccgan" / "stage.json").write_text(json.dumps({"key": {}}))
    err = refused(compare_runs.main, runs, capsys)
    assert f'{tmp_path / "b" / "ccgan" / "stage.json"} has no "files"' in err


def test_a_killed_holder_leaves_a_file_that_blocks_nothing(tmp_path):
    """kill -9 skips the holder's clean-up: its lock file stays, empty of any live owner."""
    code = HOLDER.replace("time.sleep(120)", "import os, signal; os.kill(os.getpid(), 9)")
    proc = subprocess.run(
        [sys.executable, "-c", code, run_folder.__file__, str(tmp_path / "run"), "0"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == -signal.SIGKILL
    assert run_folder.lock_path(tmp_path / "run").exists()
    start = time.monotonic()
    run_folder.lock_folder(tmp_path / "run").release()
    assert time.monotonic() - start < 1
