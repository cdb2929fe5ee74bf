"""studies.teacher_settings: its setting parser, and one tiny run end to end."""

import json

import pytest

from studies.teacher_settings import main, parse_setting


def test_parse_setting_reads_horizon_and_iterations():
    assert parse_setting("3:2") == (3, 2)
    for bad in ("3", "a:1", "0:1", "1:0", "1:2:3"):
        with pytest.raises(ValueError):
            parse_setting(bad)


def test_a_tiny_run_compares_settings_with_stretch_only(tmp_path):
    out = tmp_path / "settings"
    main(["--n", "1", "--duration", "1", "--settings", "1:1", "2:1", "--out", str(out)])
    result = json.loads(out.with_suffix(".json").read_text())
    rows = result["rows"]
    assert [(r["horizon_steps"], r["iterations"]) for r in rows] == [(1, 1), (2, 1)]
    # Both settings track better than holding the source commands, and plan in finite time.
    assert all(0 < r["x_err_cm"] < result["stretch_x_err_cm"] and r["wall_s"] > 0 for r in rows)
    assert "| 2 | 1 | " in out.with_suffix(".md").read_text()
    with pytest.raises(SystemExit):
        main(["--settings", "1", "--out", str(out)])
