"""studies.forward_data and studies.ccgan_ablation: their parsing, and one tiny run of each on a
study folder of the 3-segment arm."""

import json

import numpy as np
import pytest

from ccgan import checkpoint
from mjx_arm.babble import cli as babble_cli
from studies import ccgan_ablation, forward_data


@pytest.mark.parametrize(
    "text, run",
    [
        ("long:800:open:150", forward_data.Run("long", 800, "open", 150)),
        ("paper:50:teacher:10", forward_data.Run("paper", 50, "teacher", 10)),
    ],
)
def test_runs_parse_and_name_themselves(text, run):
    assert forward_data.Run.parse(text) == run
    assert run.name == f"{run.data}_n{run.n}_{run.mode}{run.window}"


@pytest.mark.parametrize("text", ["long:800:open", "long:800:closed:150", "long:0:open:150"])
def test_bad_runs_are_refused(text):
    with pytest.raises(ValueError):
        forward_data.Run.parse(text)


def test_epochs_give_at_least_the_steps_asked():
    assert forward_data.epochs_for(n_windows=640, batch_size=64, steps=25) == 3  # 10 per epoch
    assert forward_data.epochs_for(n_windows=10, batch_size=64, steps=5) == 5  # one per epoch


@pytest.fixture(scope="module")
def study_folder(tmp_path_factory, small_xml):
    """A study folder of the 3-segment arm: babble/ of both domains (3 + 1 programs of 3 s)."""
    folder = tmp_path_factory.mktemp("study")
    model = folder / "small.xml"
    model.write_text(small_xml)
    babble_cli.main(
        ["--domain", "both", "--n", "3", "--n-val", "1", "--duration", "3", "--seed", "0",
         "--backend", "c", "--model", str(model), "--out", str(folder / "babble"),
         "--no-progress"]
    )  # fmt: skip
    return folder, model


@pytest.mark.slow
def test_forward_data_and_the_ablation_run_end_to_end(study_folder, tmp_path, capsys):
    folder, model = study_folder
    out = tmp_path / "fdata"
    argv = ["--study-dir", str(folder), "--model", str(model), "--runs", "paper:2:teacher:5",
            "paper:3:teacher:5", "paper:3:open:10", "--steps", "3", "--batch-size", "2",
            "--hold-factors", "1", "2", "--out", str(out)]  # fmt: skip
    forward_data.main(argv)
    report = json.loads((out / "forward_data.json").read_text())
    assert [r["name"] for r in report["runs"]] == [
        "paper_n2_teacher5", "paper_n3_teacher5", "paper_n3_open10"
    ]  # fmt: skip
    for r in report["runs"]:
        assert [s["k"] for s in r["scores"]] == [1, 2]
        assert all(np.isfinite(s["kept_cm"]) and s["max_cm"] >= s["kept_cm"] for s in r["scores"])
        assert r["epochs"] * (r["windows"] // 2) >= 3  # the steps asked, at least
    _, meta = checkpoint.load(out / "paper_n3_open10" / "forward_c.ckpt")
    assert meta["config"]["open_loop"] is True and "low" in meta["bounds"]
    assert (out / "forward_data.png").stat().st_size > 0  # two N of one family: a plot
    # A rerun with the same --out keeps what is there and trains nothing again.
    forward_data.main(argv)
    assert capsys.readouterr().out.count("scored already") == 3

    # The ablation: three variants (in the order asked) with the F_c above, scored at the hold
    # factors on a held-out shape-like program.
    abl = tmp_path / "ablation"
    flags = ["--study-dir", str(folder), "--model", str(model), "--small", "--epochs", "2",
             "--stretch-every", "1", "--hold-factors", "1", "2", "--k-choice-seconds", "1",
             "--seeds", "0", "--window-length", "5", "--out", str(abl)]  # fmt: skip
    fc = out / "paper_n3_open10" / "forward_c.ckpt"
    variants = ["no feedback", "full", "no adversarial"]
    ccgan_ablation.main([*flags, "--label", "tiny", "--forward-c", str(fc), "--variants",
                         *variants, "--k-choice-programs", "shape_like",
                         "--k-choice-n-programs", "1"])  # fmt: skip
    batch = json.loads((abl / "ablation.json").read_text())["batches"]["tiny"]
    assert list(batch["variants"]) == variants
    assert batch["config"]["k_choice_programs"] == "shape_like"
    for v in batch["variants"].values():
        assert [h["epoch"] for h in v["history"]] == [1, 2]
        assert v["final_cm"] == v["history"][-1]["error_cm"]
        assert min(v["best_cm"]) >= 0 and all(k in (1, 2) for k in v["final_k"])
        assert v["stretch_only_at_final_k_cm"] == [
            batch["stretch_only_cm"][str(k)] for k in v["final_k"]
        ]
    # The removed losses reach the training: the variants do not all score alike.
    finals = [tuple(v["final_cm"]) for v in batch["variants"].values()]
    assert len(set(finals)) > 1
    md = (abl / "ablation.md").read_text()
    assert "| no feedback |" in md and "1 held-out shape-like D_s programs" in md

    # An F_c normalised with other pose bounds is refused before any training.
    params, meta = checkpoint.load(fc)
    meta["bounds"]["low"] = [x - 1.0 for x in meta["bounds"]["low"]]
    other = checkpoint.save(tmp_path / "other_fc.ckpt", params, meta)
    with pytest.raises(SystemExit):
        ccgan_ablation.main([*flags, "--label", "x", "--forward-c", str(other)])
    assert "other pose bounds" in capsys.readouterr().err


def test_fc_floor_scores_commands_window_by_window_as_the_feedback_loss():
    """studies.fc_floor: each window starts F_c at the D_s pose before it, held k periods."""
    import mjx_arm
    from ccgan import load_translator
    from mjx_arm.programs import shape_like_programs
    from studies import fc_floor
    from tracking import held, metrics

    tr = load_translator(fc_floor.DEFAULT_TRANSLATORS[0])
    programs = shape_like_programs(2, 2.0, seed=0, split="test_fc_floor").astype(np.float64)
    targets = mjx_arm.load("models/softarm.xml", "source").rollout(programs, backend="c")
    k, window = 2, 10
    got = fc_floor.feedback_view_cm(tr, programs, targets, k, window)
    assert got.shape == (2, 20)
    for i in range(2):
        for w in range(2):
            steps = slice(w * window, (w + 1) * window)
            pose0 = targets[i, max(w * window - 1, 0)]
            pred = tr.predict_poses(held.stretch(programs[i, steps], k), pose0)
            want = metrics.position_error_cm(held.every_kth(pred, k), targets[i, steps])
            np.testing.assert_allclose(got[i, steps], want, rtol=1e-4, atol=1e-5)


#: Every study command with the other flags it requires (values never read: --out is refused
#: first).
STUDY_ARGS = {
    "ccgan_ablation": ["--study-dir", "d", "--label", "l"],
    "ccgan_budget": ["--study-dir", "d"],
    "distill_runs": ["--runs", "r"],
    "error_vs_k": [],
    "error_vs_k_shapes": ["--runs", "r", "--distill-runs", "r"],
    "fc_floor": [],
    "forward_data": ["--study-dir", "d", "--runs", "long:800:open:150"],
    "forward_open_loop": ["--study-dir", "d"],
    "mpc_saturation": [],
    "oracle_start": [],
    "planning_arm": [],
    "program_length": [],
    "stretch_k": [],
    "teacher_settings": [],
    "timestep": [],
}


@pytest.mark.parametrize("name", sorted(STUDY_ARGS))
def test_every_study_refuses_an_out_it_cannot_write_before_any_work(name, tmp_path, capsys):
    """An --out under a file is a usage error naming --out, before the study reads or runs
    anything (it would otherwise fail with an OSError after minutes of simulation)."""
    import importlib

    study = importlib.import_module(f"studies.{name}")
    (tmp_path / "a_file").write_text("not a folder")
    with pytest.raises(SystemExit) as exc:
        study.main([*STUDY_ARGS[name], "--out", str(tmp_path / "a_file" / "out")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--out" in err and "is not a folder" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]
