"""bench.write_results: a benchmark's or study's .json and .md, each whole, earlier ones kept
on failure."""

import json

import pytest

from bench import write_results


def test_write_results_writes_the_header_into_both_files(tmp_path):
    header = {"device": "cpu: cpu", "command": "python -m studies.x --out y"}
    md = write_results(tmp_path / "sub" / "x", header, {"rows": [1, 2]}, "A title", ["", "| a |"])
    assert md == tmp_path / "sub" / "x.md"
    assert json.loads(md.with_suffix(".json").read_text()) == header | {"rows": [1, 2]}
    lines = md.read_text().splitlines()
    assert lines[0] == "# A title"
    assert "- command: python -m studies.x --out y" in lines
    assert lines[-1] == "| a |"


def test_a_result_that_cannot_be_written_leaves_the_earlier_files(tmp_path):
    write_results(tmp_path / "x", {}, {"rows": [1]}, "first", ["old"])
    with pytest.raises(TypeError):
        write_results(tmp_path / "x", {}, {"rows": object()}, "second", ["new"])
    assert json.loads((tmp_path / "x.json").read_text()) == {"rows": [1]}
    assert (tmp_path / "x.md").read_text().splitlines()[0] == "# first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json", "x.md"]
