"""The README's chain tables are the committed run's files, to the printed digit."""

import json

import pytest

from experiments import paper
from experiments.report import readme_tables

#: The run whose tables the README shows.
RUN = paper.REPO / "results" / "paper" / "rerun_2026-11-27" / "run"


@pytest.mark.parametrize("stage", ["table", "table_aged"])
def test_readme_holds_the_committed_runs_tables(stage):
    """Every line of `readme_tables` from the stage's shapes.json is in the README, in order:
    a rerun of the chain that changes a figure fails here until the README is regenerated."""
    readme = (paper.REPO / "README.md").read_text().splitlines()
    lines = readme_tables(json.loads((RUN / stage / "shapes.json").read_text()))
    tables = [line for line in lines if line]
    first = readme.index(tables[0])
    shown = [line for line in readme[first:] if line.startswith("|")][: len(tables)]
    assert shown == tables


def test_readme_tables_follow_the_results_they_are_made_from():
    """A changed figure changes its cell, and a method the stage did not run has no column."""
    results = json.loads((RUN / "table_aged" / "shapes.json").read_text())
    results["table"]["kite"]["ccgan_sim"]["x_err_cm_mean"] = 9.876
    lines = readme_tables(results)
    assert lines[0] == "| shape | untranslated | stretch only (k = 25) | distilled (k = 25) |"
    kite = next(line for line in lines if line.startswith("| kite |"))
    assert "| 9.88 / " in kite and "paper" not in lines[0]
