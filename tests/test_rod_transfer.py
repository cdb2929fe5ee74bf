"""`studies.rod_transfer`'s held-out programs: each family asked for, none when it is not."""

from __future__ import annotations

import numpy as np
import pytest

from studies import rod_transfer


@pytest.mark.parametrize("n_shape_like", [0, 1])
def test_the_programs_hold_each_family_asked_for(n_shape_like):
    programs, families = rod_transfer.programs_by_family(n_shape_like, 1, 2.0)
    assert programs.shape == (2 * n_shape_like + 2, 20, 3) and len(families) == len(programs)
    assert families[-2:] == ["babbling", "held"] and np.isfinite(programs).all()
    assert len(set(families[:-2])) <= 2 * n_shape_like  # the shape-like programs' kinds


def test_no_program_at_all_is_refused_before_any_work(capsys):
    with pytest.raises(SystemExit):
        rod_transfer.main(["--translators", "x=y.ckpt", "--n-shape-like", "0", "--n-other", "0",
                           "--out", "/tmp/never"])  # fmt: skip
    assert "no program to score" in capsys.readouterr().err


def test_the_chain_scores_the_families_in_its_own_medium(tmp_path):
    """`--simulator chain --target-domain aged`: stretch only's X_err per family is the aged
    chain's in MuJoCo C against the chain's own D_s path, computed here directly."""
    import json

    import mjx_arm
    from tracking.held import run_dc, stretch
    from tracking.metrics import position_error_cm

    translator = "results/paper/rerun_2026-11-27/run/aged_sim/translator_seed0.ckpt"
    rod_transfer.main([
        "--translators", f"aged_sim={translator}", "--target-domain", "aged",
        "--simulator", "chain", "--stretch-k", "5", "--n-shape-like", "0", "--n-other", "1",
        "--duration-s", "2", "--out", str(tmp_path / "t"),
    ])  # fmt: skip
    result = json.loads((tmp_path / "t.json").read_text())
    programs, _ = rod_transfer.programs_by_family(0, 1, 2.0)
    targets = mjx_arm.load(domain="source").rollout(programs, backend="c")
    poses = run_dc(mjx_arm.load(domain="aged"), stretch(programs, 5), 5, "c")
    want = position_error_cm(poses, targets).mean(-1)
    np.testing.assert_allclose(result["per_program_x_err_cm"]["stretch"], want, rtol=1e-9)
    assert result["simulator"] == "chain" and result["k"]["aged_sim"] == 25


def test_a_domain_file_sets_the_chains_medium(tmp_path):
    """`--target-domain-file` (a medium off the pair, issue 50 (c)): stretch only's X_err is that
    medium's chain in MuJoCo C; the same file with --simulator rod is refused before any work."""
    import json

    import mjx_arm
    from tracking.held import run_dc, stretch
    from tracking.metrics import position_error_cm

    medium = tmp_path / "half_drag.json"
    medium.write_text(json.dumps({"domain": {"viscosity_scale": 10.05845}}))
    rod_transfer.main([
        "--target-domain-file", str(medium), "--simulator", "chain", "--stretch-k", "5",
        "--n-shape-like", "0", "--n-other", "1", "--duration-s", "2", "--out", str(tmp_path / "t"),
    ])  # fmt: skip
    result = json.loads((tmp_path / "t.json").read_text())
    programs, _ = rod_transfer.programs_by_family(0, 1, 2.0)
    targets = mjx_arm.load(domain="source").rollout(programs, backend="c")
    arm = mjx_arm.load(domain=mjx_arm.Domain(name="half", viscosity_scale=10.05845))
    want = position_error_cm(run_dc(arm, stretch(programs, 5), 5, "c"), targets).mean(-1)
    np.testing.assert_allclose(result["per_program_x_err_cm"]["stretch"], want, rtol=1e-9)
    assert result["target_domain"] == str(medium)
    in_dc = position_error_cm(
        run_dc(mjx_arm.load(domain="constrained"), stretch(programs, 5), 5, "c"), targets
    ).mean(-1)
    assert not np.allclose(want, in_dc)  # the file's medium, not D_c's


def test_a_domain_file_is_refused_for_the_rod(tmp_path, capsys):
    medium = tmp_path / "m.json"
    medium.write_text('{"domain": {"viscosity_scale": 10.0}}')
    with pytest.raises(SystemExit):
        rod_transfer.main(["--target-domain-file", str(medium), "--out", str(tmp_path / "t")])
    assert "--simulator chain" in capsys.readouterr().err


def test_seeds_of_different_k_are_each_reported(tmp_path, monkeypatch):
    """A translator whose seeds hold different k (CCGAN-GP's choice per seed) records each."""
    import json

    class Held:
        def __init__(self, k):
            self.k = k

        def translate(self, program, target):  # stretch only at this seed's k
            return np.repeat(program, self.k, axis=0), self.k

    ks = iter([5, 10])
    monkeypatch.setattr(rod_transfer, "load_translator", lambda path: Held(next(ks)))
    rod_transfer.main([
        "--translators", "two=a.ckpt,b.ckpt", "--simulator", "chain", "--target-domain", "aged",
        "--stretch-k", "5", "--n-shape-like", "0", "--n-other", "1", "--duration-s", "2",
        "--out", str(tmp_path / "t"),
    ])  # fmt: skip
    result = json.loads((tmp_path / "t.json").read_text())
    assert result["k"] == {"stretch": 5, "two": [5, 10]}
    assert "two 5/10" in (tmp_path / "t.md").read_text()
