"""studies.error_vs_k_shapes: it reads finished runs, checks their k and puts them side by side."""

import json

import pytest

from studies.error_vs_k_shapes import main, parse_runs

SHAPES = ("circle", "kite")


def _runs_file(tmp_path, ks):
    """A studies.distill_runs result with one distillation per k (X_err falling with k)."""
    rows = [
        {
            "run": str(tmp_path / f"distill_k{k}"),
            "k": k,
            "seeds_cm": [1.0 / k, 1.2 / k, 1.1 / k],
            "teacher_cm": 0.9 / k,
            "stretch_cm": 3.0 / k,
        }
        for k in ks
    ]
    path = tmp_path / "distill_runs.json"
    path.write_text(json.dumps({"rows": rows}))
    return path


def _shapes_dir(tmp_path, k, translator_k=None):
    """An eval.shapes folder at k: stretch 2/k, the tracker 0.5/k, the translator 0.8/k cm."""
    folder = tmp_path / f"shapes_k{k}"
    folder.mkdir()
    errors = {"stretch": 2.0 / k, "mpc": 0.5 / k, "ccgan_sim": 0.8 / k}
    held = {"stretch": k, "mpc": k, "ccgan_sim": translator_k or k}
    table = {
        shape: {m: {"x_err_cm_mean": errors[m], "k": held[m]} for m in errors} for shape in SHAPES
    }
    (folder / "shapes.json").write_text(json.dumps({"table": table}))
    return folder


def test_parse_runs_reads_both_folders_by_k():
    runs = parse_runs(["15=a:b", "10=c:d"])
    assert {k: tuple(map(str, v)) for k, v in runs.items()} == {15: ("a", "b"), 10: ("c", "d")}
    for bad in (["a:b"], ["x=a:b"], ["0=a:b"], ["15=a"], ["15=:b"], ["15=a:b", "15=c:d"]):
        with pytest.raises(ValueError):
            parse_runs(bad)


def test_runs_side_by_side_with_their_ratios(tmp_path):
    runs_file = _runs_file(tmp_path, (10, 20))
    args = [f"{k}={tmp_path / f'distill_k{k}'}:{_shapes_dir(tmp_path, k)}" for k in (10, 20)]
    out = tmp_path / "vs_k"
    main(["--distill-runs", str(runs_file), "--runs", *args, "--out", str(out)])
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["held_out"]["10"]["mean"] == pytest.approx(0.11)
    assert result["held_out"]["20"]["stretch"] == pytest.approx(0.15)
    assert result["shapes"]["20"]["kite"]["ccgan_sim"] == pytest.approx(0.04)
    lines = out.with_suffix(".md").read_text().splitlines()
    k10 = next(line for line in lines if line.startswith("| 10 | 600 |"))
    # held out: 0.11 / 0.09 teacher = 1.22, / 0.3 stretch = 0.37; shapes: 0.08 / 0.05 = 1.60
    assert "| 1.22 | 0.37 |" in k10 and k10.endswith("| 1.60 | 0.40 |")
    assert out.with_suffix(".png").stat().st_size > 0


def test_a_table_at_another_k_is_refused(tmp_path, capsys):
    runs_file = _runs_file(tmp_path, (10,))
    shapes = _shapes_dir(tmp_path, 10, translator_k=15)
    with pytest.raises(SystemExit):
        main(
            ["--distill-runs", str(runs_file), "--runs", f"10={tmp_path / 'distill_k10'}:{shapes}"]
            + ["--out", str(tmp_path / "x")]
        )
    assert "not held k = 10" in capsys.readouterr().err


def test_a_distillation_missing_from_the_study_is_refused(tmp_path, capsys):
    runs_file = _runs_file(tmp_path, (10,))
    shapes = _shapes_dir(tmp_path, 20)
    with pytest.raises(SystemExit):
        main(
            ["--distill-runs", str(runs_file), "--runs", f"20={tmp_path / 'distill_k20'}:{shapes}"]
            + ["--out", str(tmp_path / "x")]
        )
    assert "not a distillation at k = 20" in capsys.readouterr().err
