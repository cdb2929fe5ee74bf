"""studies.distill_runs: runs' rows from their distill.json, stretch only rebuilt where a run
did not record it, once per set of held-out programs."""

import json
from pathlib import Path

import numpy as np
import pytest

import mjx_arm
from ccgan.distill import DistillConfig, held_out_programs
from studies.distill_runs import main
from tracking import held, metrics

#: A committed run's record on models/softarm.xml (held-out programs of 60 s: too long here).
COMMITTED = "studies/results/h100/issue30/distill_k10/distill.json"


def tiny_run(folder, stretch=None, n_val=1):
    """A committed run's record with 1-2 held-out programs of 0.3 s at k = 2."""
    run = json.loads(Path(COMMITTED).read_text())
    run["config"] |= {"n_val": n_val, "n_val_full": 0, "duration_s": 0.3, "window_s": 0.3}
    run["history"]["k"] = 2
    if stretch is not None:
        run["history"]["stretch_val_x_err_cm"] = {"whole": stretch, "window": stretch}
    folder.mkdir()
    (folder / "distill.json").write_text(json.dumps(run))
    return run


def test_rows_give_ratios_and_stretch_only_is_rebuilt_once(tmp_path, capsys):
    run = tiny_run(tmp_path / "a")
    tiny_run(tmp_path / "b")  # the same held-out programs: stretch only is not computed again
    tiny_run(tmp_path / "c", stretch=2.0)  # recorded by the run: read, not computed
    tiny_run(tmp_path / "d", n_val=2)  # other held-out programs
    out = tmp_path / "runs"
    main(["--runs", *(str(tmp_path / x) for x in "abcd"), "--out", str(out)])
    assert capsys.readouterr().out.count("stretch only for") == 2
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]

    arm_s, arm_c = (mjx_arm.load("models/softarm.xml", d) for d in ("source", "constrained"))
    programs = held_out_programs(DistillConfig(**run["config"]))
    poses = held.run_dc(arm_c, held.stretch(programs, 2), 2, "c")
    want = metrics.position_error_cm(poses, arm_s.rollout(programs, backend="c")).mean()
    assert rows[0]["stretch_cm"] == rows[1]["stretch_cm"] == pytest.approx(want, rel=1e-9)
    assert rows[2]["stretch_cm"] == 2.0 and rows[2]["stretch_source"] == "recorded by the run"
    assert rows[3]["held_out_programs"] == 2 and rows[3]["stretch_cm"] != rows[0]["stretch_cm"]
    best = np.asarray(run["history"]["best_val_x_err_cm"])
    np.testing.assert_allclose(rows[2]["over_stretch"], best / 2.0)
    np.testing.assert_allclose(
        rows[0]["over_teacher"], best / run["history"]["teacher_val_x_err_cm"]["whole"]
    )
    assert out.with_suffix(".md").read_text().count("| constrained | 2 |") == 4


def test_a_folder_without_a_run_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--runs", str(tmp_path), "--out", str(tmp_path / "o")])
    assert stop.value.code == 2 and "distill.json" in capsys.readouterr().err
