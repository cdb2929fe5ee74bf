"""studies.error_vs_k: its translator-set parser, and one tiny run end to end."""

import json

import pytest

from studies.error_vs_k import main, parse_sets

#: A translator distilled at k = 15 on models/softarm.xml (committed).
DISTILLED = "studies/results/h200/issue30/distill_k15/translator_seed0.ckpt"


def test_parse_sets_reads_files_by_k():
    assert parse_sets(["15=a.ckpt,b.ckpt", "10=c.ckpt"]) == {
        15: ["a.ckpt", "b.ckpt"],
        10: ["c.ckpt"],
    }
    for bad in (["a.ckpt"], ["x=a.ckpt"], ["0=a.ckpt"], ["15="], ["15=a", "15=b"]):
        with pytest.raises(ValueError):
            parse_sets(bad)


def test_a_tiny_run_gives_every_method_at_every_k(tmp_path):
    out = tmp_path / "k"
    args = ["--ks", "2", "15", "--n", "1", "--duration", "1", "--translators", f"15={DISTILLED}"]
    main(args + ["--out", str(out)])
    result = json.loads(out.with_suffix(".json").read_text())
    assert [row["k"] for row in result["rows"]] == [2, 15]
    for row in result["rows"]:
        assert row["d_c_seconds_per_program"] == row["k"]
        assert row["teacher"] < row["stretch"]
        assert len(row["translators"]["15"]["per_seed"]) == 1
    text = out.with_suffix(".md").read_text()
    assert "(held at k)" in text.splitlines()[-2] and "(held at k)" not in text.splitlines()[-1]
    assert out.with_suffix(".png").stat().st_size > 0


def test_a_translator_of_another_arm_is_refused(capsys):
    """The chain's CCGAN-GP of the previous model is not scored on models/softarm.xml."""
    old_arm = "results/paper/run/ccgan/translator_seed0.ckpt"
    with pytest.raises(SystemExit):
        main(["--ks", "15", "--translators", f"5={old_arm}", "--out", "unused"])
    assert "--translators" in capsys.readouterr().err
