"""`studies.shape_ratios`: the five shapes' X_err of methods from several eval folders, and
their ratios to the baselines; folders of different media are refused."""

from __future__ import annotations

import json

import pytest

from studies import shape_ratios


def a_folder(path, medium: str, errors: dict[str, float]):
    """A folder with a shapes.json whose every shape has each method's X_err."""
    path.mkdir()
    table = {s: {m: {"x_err_cm_mean": e} for m, e in errors.items()} for s in shape_ratios.SHAPES}
    (path / "shapes.json").write_text(json.dumps({"table": table, "target_domain_file": medium}))
    return path


def test_ratios_to_each_baseline_and_not_between_baselines(tmp_path):
    a = a_folder(tmp_path / "a", "m.json", {"stretch": 2.0, "ccgan_ident": 0.5})
    b = a_folder(tmp_path / "b", "m.json", {"ccgan_ident": 0.25})
    shape_ratios.main([
        "--column", f"stretch={a}:stretch", f"data={a}:ccgan_ident", f"priv={b}:ccgan_ident",
        "--baseline", "stretch", "priv", "--out", str(tmp_path / "r"),
    ])  # fmt: skip
    ratios = json.loads((tmp_path / "r.json").read_text())["ratios"]
    assert set(ratios) == {"data / stretch", "priv / stretch", "data / priv"}
    assert ratios["data / stretch"]["kite"] == pytest.approx(0.25)
    assert ratios["data / priv"]["circle"] == pytest.approx(2.0)


def test_folders_of_two_media_or_a_missing_method_are_refused(tmp_path, capsys):
    a = a_folder(tmp_path / "a", "m.json", {"stretch": 2.0})
    b = a_folder(tmp_path / "b", "other.json", {"stretch": 1.0})
    for columns, message in (
        ([f"x={a}:stretch", f"y={b}:stretch"], "different media"),
        ([f"x={a}:oracle"], "has no oracle"),
    ):
        with pytest.raises(SystemExit):
            shape_ratios.main(
                ["--column", *columns, "--baseline", "x", "--out", str(tmp_path / "r")]
            )
        assert message in capsys.readouterr().err
