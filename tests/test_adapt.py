"""`python -m ccgan.adapt`: from a new arm's logs to a translator (identify, then distil in the
identified arm), and `ccgan.distill --domain identified`."""

from __future__ import annotations

from pathlib import Path

import pytest

import mjx_arm  # noqa: F401  (before jax)
from ccgan import adapt, distill
from mjx_arm.domains import IDENTIFIED


def _touch(folder, *names):
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        (folder / name).write_bytes(b"")
    return folder


def test_the_logs_domain_is_the_only_one_besides_the_source(tmp_path):
    both = _touch(tmp_path / "both", "source_train.npz", "constrained_train.npz")
    assert adapt.data_domain(both, None) == "constrained"
    assert adapt.data_domain(both, "source") == "source"  # asked: taken as given
    aged = _touch(tmp_path / "aged", "aged_train.npz", "aged_val.npz")
    assert adapt.data_domain(aged, None) == "aged"
    assert adapt.data_domain(aged / "aged_train.npz", None) == ""  # a file names itself
    two = _touch(tmp_path / "two", "aged_train.npz", "constrained_train.npz")
    with pytest.raises(ValueError, match="give --data-domain"):
        adapt.data_domain(two, None)
    with pytest.raises(ValueError, match="no <domain>_train.npz besides source"):
        adapt.data_domain(_touch(tmp_path / "src", "source_train.npz"), None)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--data", "{tmp}/nothing", "--out", "{tmp}/o"], "no such file or folder"),
        (["--data", "{tmp}/two", "--out", "{tmp}/o"], "give --data-domain"),
        (
            ["--data", "{tmp}/aged", "--out", "{tmp}/o", "--translators", "{tmp}/none.ckpt"],
            "is not a file",
        ),
        (["--data", "{tmp}/aged", "--out", "{tmp}/o", "--t63", "-3"], "--t63 must be"),
    ],
)
def test_bad_input_is_a_usage_error_before_any_work(tmp_path, capsys, argv, message):
    _touch(tmp_path / "two", "aged_train.npz", "constrained_train.npz")
    _touch(tmp_path / "aged", "aged_train.npz")
    with pytest.raises(SystemExit) as exc:
        adapt.main([a.format(tmp=tmp_path) for a in argv])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_k_from_the_step_time_is_the_rules_nearest_candidate():
    """The rod's step times (36.2 s in D_c, 50.7 s aged) give its best k, 20 and 25; the
    chain's D_c (32.6 s) its 15."""
    candidates = adapt.K_CANDIDATES
    assert [adapt.k_from_step_time(t, candidates) for t in (32.6, 36.2, 50.7)] == [15, 20, 25]
    assert adapt.k_from_step_time(36.2, (10, 15)) == 15  # only among the candidates


def test_the_default_start_translators_are_committed_files():
    defaults = adapt.build_parser().parse_args(["--data", "d", "--out", "o"]).translators
    assert len(defaults) == len(adapt.START_SEEDS)
    assert all(Path(p).is_file() for p in defaults)


def test_distill_refuses_an_identified_target_without_its_file(tmp_path, capsys):
    argv = [
        "--translators",
        *adapt.build_parser().parse_args(["--data", "d", "--out", "o"]).translators,
    ]
    argv += ["--domain", IDENTIFIED, "--hold-factor", "15", "--out", str(tmp_path / "o")]
    with pytest.raises(SystemExit) as exc:
        distill.main(argv)
    assert exc.value.code == 2
    assert f"--domain {IDENTIFIED} needs --teach-domain" in capsys.readouterr().err


@pytest.mark.slow
def test_logs_of_an_aged_arm_become_a_translator_labelled_identified(tmp_path):
    """The whole path, tiny (--quick), on logs of the aged arm: the identification finds its
    stiffness, and the translator is labelled for "identified", records the file it was taught
    on, and is refused as a D_c translator (about 3 minutes on one core, mostly compiles)."""
    import json

    import ccgan
    from ccgan.checkpoint import CheckpointError
    from mjx_arm.babble import cli as babble

    logs = tmp_path / "logs"
    assert babble.main(["--domain", "aged", "--n", "3", "--n-val", "1", "--duration", "8",
                        "--backend", "c", "--out", str(logs)]) in (0, None)  # fmt: skip
    assert adapt.main(["--data", str(logs), "--out", str(tmp_path / "a"), "--quick"]) == 0
    report = json.loads((tmp_path / "a" / "identify" / "identify.json").read_text())
    assert report["results"]["search"]["values"]["stiffness_scale"] == pytest.approx(0.7, rel=1e-3)
    path = tmp_path / "a" / "translator" / "translator.ckpt"
    translator = ccgan.load_translator(path, method="distill", target_domain=IDENTIFIED)
    assert translator.k in adapt.K_CANDIDATES
    with pytest.raises(CheckpointError):
        ccgan.load_translator(path, method="distill", target_domain="constrained")
    summary = json.loads((tmp_path / "a" / "adapt.json").read_text())
    assert summary["total_s"] >= summary["identify_s"] > 0
