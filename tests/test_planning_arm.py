"""Planning copies of the arm (`Arm.planning_copy`): fewer physics steps per control period for
the teacher and the oracle, whose commands are scored in the arm itself (CPU, MuJoCo C)."""

import dataclasses
import json

import numpy as np
import pytest

import mjx_arm
from ccgan import distill
from eval import shapes
from mjx_arm.programs import validation_program
from studies import planning_arm
from tracking import oracle
from tracking.oracle import OracleConfig


@pytest.fixture(scope="module")
def arm_c():
    return mjx_arm.load(domain="constrained")


def test_a_planning_copy_steps_less_and_moves_as_the_arm(arm_c):
    copy = arm_c.planning_copy(5)
    assert (copy.n_substeps, copy.timestep_s) == (5, pytest.approx(0.02))
    assert copy.model_hash == arm_c.model_hash + "-s5" and copy.domain == arm_c.domain
    assert arm_c.planning_copy(5) is copy and arm_c.planning_copy(0) is arm_c  # kept; 0: itself
    # The automatic inertia scale follows the longer step (explicit Euler stays stable).
    assert copy.inertia_scale > 4 * arm_c.inertia_scale
    program = np.repeat(validation_program(duration_s=4.0), 5, axis=0)
    tip, tip_copy = arm_c.rollout(program, backend="c"), copy.rollout(program, backend="c")
    moved = np.linalg.norm(tip[-1, :3] - tip[0, :3])
    gap = np.linalg.norm(tip[4::5, :3] - tip_copy[4::5, :3], axis=-1)  # after each held step
    assert moved > 0.02 and 0 < gap.mean() < 1e-4 and gap.max() < 1e-3  # centimetres against
    # a tenth of a millimetre on average
    # From a string as from a file; the same copy either way.
    from_text = mjx_arm.load(xml=arm_c.mjcf_text, domain="constrained").planning_copy(5)
    assert from_text.model_hash == copy.model_hash


@pytest.mark.parametrize("bad", [0, -1, 2.5, True])
def test_load_refuses_a_step_count_that_is_not_a_positive_integer(bad):
    with pytest.raises(ValueError, match="substeps"):
        mjx_arm.load(domain="constrained", substeps=bad)


def test_the_teacher_plans_in_the_copy_under_its_own_cache_key(small_xml, tmp_path, monkeypatch):
    arm_s = mjx_arm.load(xml=small_xml, domain="source")
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    config = distill.DistillConfig(
        n_train=1, n_val=1, duration_s=0.5, batch_size=1, hold_factor=5, teacher_substeps=5
    )
    planned_in = []
    track = distill.mpc.track

    def spy(arm, *args, **kwargs):
        planned_in.append(arm)
        return track(arm, *args, **kwargs)

    monkeypatch.setattr(distill.mpc, "track", spy)
    cache = tmp_path / "teacher.npz"
    data = distill.teacher_data(config, arm_s, arm_c, 5, cache, log=lambda _: None)
    assert [a.n_substeps for a in planned_in] == [5, 5]  # a call per split
    with np.load(cache) as f:
        key = json.loads(str(f["key"]))
    assert key["teacher_substeps"] == 5 and key["model"] == arm_c.model_hash
    # The arm itself keeps the old key (caches planned before the field stay valid).
    plain = dataclasses.replace(config, teacher_substeps=0)
    assert "teacher_substeps" not in plain.teacher_key()
    assert np.isfinite(data["teacher_val_x_err_cm"]).all()
    with pytest.raises(distill.ConfigError, match="teacher_substeps"):
        dataclasses.replace(config, teacher_substeps=-1)


def test_the_oracle_differentiates_through_the_copy(small_xml, monkeypatch):
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    seen = []

    class Compiled(Exception):
        pass

    def stop_before_compiling(arm, *args):
        seen.append(arm)
        raise Compiled

    monkeypatch.setattr(oracle, "_adam_step", stop_before_compiling)
    targets = np.tile(arm_c.rest_pose(), (2, 1))
    inits = np.full((2, 3), 1.0)
    with pytest.raises(Compiled):
        oracle.oracle_commands(arm_c, targets, inits, 1, OracleConfig(steps=1, substeps=3))
    assert seen[0].n_substeps == 3
    # Progress kept without a copy keeps its fingerprint; a copy's differs.
    args = (targets, inits, np.array(True), 1)
    plain = oracle._fingerprint(arm_c, *args, OracleConfig())
    assert plain != oracle._fingerprint(seen[0], *args, OracleConfig(substeps=3))
    with pytest.raises(oracle.ConfigError, match="oracle.substeps"):
        OracleConfig(substeps=-1)


def test_eval_shapes_sets_the_oracle_copy_and_names_a_bad_flag(capsys):
    assert shapes.parse_args(["--oracle-substeps", "5"]).oracle.substeps == 5
    assert shapes.parse_args([]).oracle.substeps == 0
    with pytest.raises(SystemExit):
        shapes.parse_args(["--oracle-substeps", "-2"])
    assert "--oracle-substeps must be an integer >= 0" in capsys.readouterr().err


def test_planning_arm_study_writes_its_rows(tmp_path):
    out = tmp_path / "planning"
    argv = ["--domains", "constrained", "--substeps", "25", "5", "--teacher-programs", "1"]
    planning_arm.main([*argv, "--duration-s", "1", "--out", str(out)])
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]
    assert [r["substeps"] for r in rows] == [25, 5]
    assert rows[0]["tip_max_mm"] == 0.0 and 0 < rows[1]["tip_max_mm"] < 1.0
    assert rows[1]["teacher_x_err_cm"] == pytest.approx(rows[0]["teacher_x_err_cm"], rel=0.2)
    assert "| constrained | 15 | 5 | 20 |" in out.with_suffix(".md").read_text()


def test_a_table_adopts_an_earlier_stage_s_caches_but_keeps_its_own(tmp_path, capsys):
    source, out = tmp_path / "oracle", tmp_path / "table"
    source.mkdir()
    (source / "mpc_commands.npz").write_bytes(b"planned")
    (source / "oracle_progress.npz").write_bytes(b"adam")
    out.mkdir()
    (out / "oracle_progress.npz").write_bytes(b"own")
    assert shapes.adopt_caches(source, out) == ["mpc_commands.npz"]
    assert (out / "mpc_commands.npz").read_bytes() == b"planned"
    assert (out / "oracle_progress.npz").read_bytes() == b"own"
    assert shapes.adopt_caches(source, out) == []  # a second call adopts nothing
    with pytest.raises(FileNotFoundError, match="holds none of"):
        shapes.adopt_caches(tmp_path / "nothing", tmp_path / "elsewhere")
    with pytest.raises(SystemExit):
        shapes.main(["--caches-from", str(source)])
    assert "--caches-from needs --out" in capsys.readouterr().err


def test_ccgan_train_scores_k_in_the_copy_when_asked(monkeypatch):
    from types import SimpleNamespace

    from ccgan import sim_choice, train
    from ccgan.config import TrainConfig

    made = []
    monkeypatch.setattr(sim_choice, "SimulatorChoice", lambda arm, *a, **kw: made.append(arm))
    args = SimpleNamespace(model="models/softarm.xml", no_progress=True)
    d_c = SimpleNamespace(domain="constrained", model_hash=mjx_arm.load().model_hash)
    for substeps, want in ((0, 25), (5, 5)):
        config = TrainConfig(k_choice_substeps=substeps)
        train.simulator_choice_from_args(None, args, config, None, d_c)
        assert made[-1].n_substeps == want and made[-1].domain.name == "constrained"


def test_distill_scores_its_held_out_programs_in_the_copy(arm_c, tmp_path, monkeypatch):
    """On the committed arm (the 3-segment test arm is far stiffer for its inertia, and a copy
    of 5 steps moves it differently)."""
    from ccgan import load_translator

    arm_s = mjx_arm.load(domain="source")
    config = distill.DistillConfig(
        n_train=2, n_val=1, duration_s=0.5, epochs=1, batch_size=2, eval_every=1, hold_factor=5,
        score_substeps=5,
    )  # fmt: skip
    scored_in = []
    make_validation = distill.make_validation

    def spy(translator, arm, *args):
        scored_in.append(arm.n_substeps)
        return make_validation(translator, arm, *args)

    monkeypatch.setattr(distill, "make_validation", spy)
    cache = tmp_path / "teacher.npz"
    shipped = load_translator()
    _, in_copy = distill.distill([shipped], arm_s, arm_c, config, cache=cache, progress=False)
    plain = dataclasses.replace(config, score_substeps=0)
    _, in_arm = distill.distill([shipped], arm_s, arm_c, plain, cache=cache, progress=False)
    assert scored_in == [5, 25]
    copy_x, arm_x = in_copy["teacher_val_x_err_cm"], in_arm["teacher_val_x_err_cm"]
    assert copy_x["whole"] == pytest.approx(arm_x["whole"], rel=0.05)
    assert copy_x["whole"] != arm_x["whole"]  # scored in another arm
    with pytest.raises(distill.ConfigError, match="score_substeps"):
        dataclasses.replace(config, score_substeps=-1)
