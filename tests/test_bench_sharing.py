"""bench.sharing: the throughput arithmetic, and a failed training's output in the error."""

import argparse
import json
import sys

import pytest

from bench import sharing


def fake_training(epoch_s: float):
    """A train_command stand-in: writes the train_paper.json bench.train would write."""

    def command(args, out):
        code = (
            "import json, pathlib, sys; out = pathlib.Path(sys.argv[1]); out.mkdir(parents=True);"
            f" run = {{'epoch_s': {epoch_s}, 'compile_s': 1.0}};"
            " (out / 'train_paper.json').write_text(json.dumps({'paper_run': run}))"
        )
        return [sys.executable, "-c", code, str(out)]

    return command


def test_throughput_compares_the_trainings_together_with_one_alone(tmp_path, monkeypatch):
    args = argparse.Namespace(epochs=3, seeds=1, out=str(tmp_path / "sharing"))
    monkeypatch.setattr(sharing, "train_command", fake_training(2.0))
    rows = []
    for n in (1, 4):
        (tmp_path / f"n{n}").mkdir()
        rows.append(sharing.run_together(args, n, tmp_path / f"n{n}"))
    rows[1]["epoch_s"] = [4.0, 4.0, 4.0, 4.0]  # four at once, each twice as slow as alone
    md = sharing.write_report(args, {"device": "test"}, rows)
    result = json.loads(md.with_suffix(".json").read_text())
    assert [r["throughput_vs_alone"] for r in result["rows"]] == [1.0, 2.0]
    assert "| 4 | 4.000, 4.000, 4.000, 4.000 |" in md.read_text()


def test_a_failed_training_stops_the_bench_with_its_output(tmp_path, monkeypatch):
    args = argparse.Namespace(epochs=3, seeds=1, out=str(tmp_path / "sharing"))
    failing = [sys.executable, "-c", "print('no GPU memory left'); raise SystemExit(3)"]
    monkeypatch.setattr(sharing, "train_command", lambda a, out: failing)
    with pytest.raises(RuntimeError, match="no GPU memory left"):
        sharing.run_together(args, 2, tmp_path)


def test_jobs_must_include_one_alone():
    with pytest.raises(SystemExit):
        sharing.main(["--jobs", "2", "4", "--out", "x"])
