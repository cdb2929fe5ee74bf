"""The README's chain tables are the committed run's files, to the printed digit."""

import json

import pytest

from experiments import paper
from experiments.report import ROD_NAMES, readme_tables

#: The run whose tables the README shows.
RUN = paper.REPO / "results" / "paper" / "rerun_2026-11-27" / "run"


#: The tables scored in the reference rod with the committed chain's translators.
ROD_RUN = paper.REPO / "results" / "paper" / "rod_chain_2026-11-28"


@pytest.mark.parametrize(
    "folder, tables_shown",
    [(RUN / "table", 2), (RUN / "table_aged", 1), (ROD_RUN / "rod_table", 1)],
)
def test_readme_holds_the_committed_runs_tables(folder, tables_shown):
    """Every line of the README's `readme_tables` from the stage's shapes.json is in the README,
    in order (the aged arm's and the rod's X_err table; their % tables are in their reports):
    a rerun that changes a figure fails here until the README is regenerated."""
    readme = (paper.REPO / "README.md").read_text().splitlines()
    names = ROD_NAMES if folder.parent == ROD_RUN else None
    lines = readme_tables(json.loads((folder / "shapes.json").read_text()), names)
    if tables_shown == 1:
        lines = lines[: lines.index("")]
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
