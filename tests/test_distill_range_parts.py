"""ccgan.distill_range's teacher in parts: processes planning different k (`only_ks`) write
their own caches, and the run that trains takes their shards (`teacher_from`) instead of
planning; a part planned otherwise is skipped and left where it is."""

import numpy as np
import pytest

import mjx_arm
from ccgan.distill.config import DistillConfig
from ccgan.distill_range import teacher as range_teacher
from ccgan.distill_range.media import Medium

CONFIG = DistillConfig(
    teacher_backend="mjx", duration_s=0.5, n_train=1, n_val=1, batch_size=1, window_s=0.5
)
MEDIA = [Medium(3.0, 1.0, 6.0, 5), Medium(6.0, 0.9, 12.0, 10), Medium(4.0, 0.8, 9.0, 5)]


@pytest.fixture
def arms(small_xml):
    return mjx_arm.load(xml=small_xml, domain="source"), mjx_arm.load(xml=small_xml)


def fake_track(calls):
    """A stand-in for `mpc_mjx.track`: each program's commands are its k, held k periods."""

    def track(plan_arm, targets, k, programs, cfg, **kw):
        calls.append(k)
        commands = np.full((len(programs), programs.shape[1] * k, 3), float(k))
        return commands, {"healthy": np.ones(len(programs), bool)}

    return track


def test_parts_plan_their_k_and_the_training_run_takes_them(arms, tmp_path, monkeypatch):
    arm_s, arm_c = arms
    calls = []
    monkeypatch.setattr(range_teacher.mpc_mjx, "track", fake_track(calls))
    for k in (5, 10):
        range_teacher.teacher_over_media(
            CONFIG, MEDIA, arm_s, arm_c, tmp_path / f"k{k}" / "teacher.npz", log=len,
            only_ks=(k,),
        )  # fmt: skip
    assert calls == [5, 10]
    calls.clear()
    logs = []
    parts = (tmp_path / "k5" / "teacher.npz", tmp_path / "k10" / "teacher.npz")
    main_cache = tmp_path / "main" / "teacher.npz"
    got = range_teacher.teacher_over_media(
        CONFIG, MEDIA, arm_s, arm_c, main_cache, log=logs.append, teacher_from=parts
    )
    assert calls == []  # nothing planned again
    ks = np.array([m.k for m in MEDIA])[got["medium"]]
    np.testing.assert_array_equal(got["c"], np.broadcast_to(ks[:, None, None], got["c"].shape))
    assert any("c_k5_0 from" in line and "c_k10_0 from" in line for line in logs)
    # The joined shards are this run's now: it reads them without the parts.
    again = range_teacher.teacher_over_media(CONFIG, MEDIA, arm_s, arm_c, main_cache, log=len)
    np.testing.assert_array_equal(again["c"], got["c"])
    assert calls == []


def test_a_part_planned_otherwise_is_skipped_and_left_alone(arms, tmp_path, monkeypatch):
    arm_s, arm_c = arms
    calls = []
    monkeypatch.setattr(range_teacher.mpc_mjx, "track", fake_track(calls))
    other = DistillConfig(**{**CONFIG.__dict__, "seed": 1})
    part = tmp_path / "other" / "teacher.npz"
    range_teacher.teacher_over_media(other, MEDIA, arm_s, arm_c, part, log=len, only_ks=(5,))
    calls.clear()
    logs = []
    range_teacher.teacher_over_media(
        CONFIG, MEDIA, arm_s, arm_c, tmp_path / "main" / "teacher.npz", log=logs.append,
        teacher_from=(part, tmp_path / "missing" / "teacher.npz"),
    )  # fmt: skip
    assert sorted(calls) == [5, 10]  # planned itself
    assert part.is_file()  # another run's file: not moved aside
    assert any("planned otherwise" in line and "seed" in line for line in logs)
    assert any("no such file" in line for line in logs)
    with pytest.raises(ValueError, match="the media's k are"):
        range_teacher.teacher_over_media(CONFIG, MEDIA, arm_s, arm_c, None, only_ks=(7,))


def test_the_cli_refuses_a_part_of_a_k_no_medium_has(tmp_path, capsys):
    from ccgan.distill_range import main

    with pytest.raises(SystemExit) as exit_info:
        main(["--out", str(tmp_path / "part"), "--quick", "--teacher-ks", "7"])
    assert exit_info.value.code == 2
    assert "--teacher-ks [7]: the training media's k are [5, 10]" in capsys.readouterr().err


def test_the_one_gpu_settings_parse_with_a_batch_over_all_media(tmp_path):
    """PAPER_SETTINGS train 80 programs per step over 24 media of 10 + 10: the batch is checked
    against all of them, not one medium's 20 (which refused the default command)."""
    from ccgan.distill_range import cli

    _, _, range_config, config = cli.parse(["--out", str(tmp_path / "r")])
    assert config.batch_size == 80 and config.train_sets == range_config.n_media == 24
    with pytest.raises(SystemExit):
        cli.parse(["--out", str(tmp_path / "s"), "--n-media", "3"])  # 80 > 3 x 20
