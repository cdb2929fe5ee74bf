"""studies.correction_transfer: the rod's difference from an arm along two translators' commands
and stretch only's, by family; the same translator twice differs by nothing."""

import json

import pytest

from studies import correction_transfer

U0 = "studies/results/h200/rod_source/chain_source/translator_seed0.ckpt"
U1 = "studies/results/h200/rod_source/rod_source/translator_seed0.ckpt"
IDENTIFIED = "results/paper/chain_2026-11-28/run/identify_rod/identify.json"


def test_one_translator_twice_differs_by_nothing_and_stretch_only_differs(tmp_path):
    out = tmp_path / "ct"
    argv = ["--teach-domain", IDENTIFIED, "--u0", U0, "--u1", U0, "--out", str(out)]
    correction_transfer.main([*argv, "--n-shape-like", "1", "--n-other", "0", "--duration-s", "1"])
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]
    assert set(rows) >= {"all"} and rows["all"]["n"] == 2
    assert rows["all"]["d_u1_minus_d_u0_cm"] == 0.0
    assert rows["all"]["arm_u1_minus_arm_u0_cm"] == 0.0
    assert rows["all"]["d_u0_cm"] > 0.0  # the rod is not the identified arm
    assert rows["all"]["arm_stretch_minus_arm_u0_cm"] > 0.0  # stretch only's commands differ
    assert "| all | 2 |" in out.with_suffix(".md").read_text()


def test_translators_of_different_k_are_refused(tmp_path):
    other_k = "results/paper/rerun_2026-11-27/run/ccgan/translator_seed0.ckpt"  # k = 15
    argv = ["--teach-domain", IDENTIFIED, "--u0", U0, "--u1", other_k, "--out", str(tmp_path / "x")]
    with pytest.raises(SystemExit):
        correction_transfer.main(argv)


def test_the_corrected_teachers_are_scored_in_the_rod_beside_stretch_only(tmp_path):
    from studies import correction_teacher

    out = tmp_path / "teacher"
    argv = ["--teach-domain", IDENTIFIED, "--u0", U0, "--out", str(out), "--n-other", "0"]
    correction_teacher.main([*argv, "--duration-s", "1"])
    result = json.loads(out.with_suffix(".json").read_text())
    row = result["rows"]["all"]
    names = ["stretch", "u0 (translator)", "teacher x_chain", "teacher x_chain - d0"]
    assert set(row) == {"n", *names, "teacher x_rod - d0"} and row["n"] == 2
    per_program = result["per_program_x_err_cm"]
    for name in names:
        assert abs(row[name] - sum(per_program[name]) / 2) < 1e-12  # the mean of its programs
    # The uncorrected teacher meets its own target in the arm, the corrected ones theirs.
    assert all(e < row["stretch"] for e in result["teacher_x_err_in_arm_cm"]["teacher x_chain"])
