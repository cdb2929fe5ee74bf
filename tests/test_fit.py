"""The fit of the MuJoCo arm to the reference rod: recovers known parameters, stored safely."""

import json

import numpy as np
import pytest

from mjx_arm import fit, fitted
from mjx_arm.programs import held_program


def test_fit_recovers_the_media_of_a_known_arm():
    # Targets from the MuJoCo arm itself at a known drag and constrained scale: the fit, started
    # from the physical values, must find them (stiffness and gain stay at their prior).
    programs = held_program(7, seconds=6.0, hold_periods=(5, 20))[None]
    data = {d: {"programs": programs} for d in fit.FIT_DOMAINS}
    truth = fit.initial_log() + np.log([1.0, 1.0, 1.3, 1.5])
    poses = fit.simulate(fit.params_from_log(truth), data)
    for d in fit.FIT_DOMAINS:
        data[d]["poses"] = poses[d]
    result = fit.fit(data, max_iter=15, log=lambda _: None)
    found = np.log([result["fitted"][name] for name in fit.NAMES])
    np.testing.assert_allclose(found, truth, atol=0.03)
    for d in fit.FIT_DOMAINS:
        assert result["fit_error_after"][d]["tip_rms_m"] < 2e-5
        assert (
            result["fit_error_after"][d]["tip_rms_m"] < result["fit_error_before"][d]["tip_rms_m"]
        )


def test_committed_fit_drives_the_defaults():
    import mjx_arm
    from mjx_arm import ArmParams

    stored = fitted.load_fit()
    assert ArmParams().stiffness_scale == stored["stiffness_scale"]
    assert ArmParams().medium_drag_ns_per_m2 == stored["medium_drag_ns_per_m2"]
    # The constrained medium travels in the model and is applied on load.
    source, constrained = mjx_arm.load(), mjx_arm.load(domain="constrained")
    ratio = constrained.mj_model.opt.viscosity / source.mj_model.opt.viscosity
    assert ratio == pytest.approx(stored["constrained_viscosity_scale"], rel=1e-5)
    # The frozen solid arm has no such field and keeps its own fitted scale.
    solid = fitted.load_fit(fitted.FIT_PATHS["solid"])
    s_src = mjx_arm.load(mjx_arm.constants.SOLID_MODEL_PATH)
    s_con = mjx_arm.load(mjx_arm.constants.SOLID_MODEL_PATH, domain="constrained")
    ratio = s_con.mj_model.opt.viscosity / s_src.mj_model.opt.viscosity
    assert ratio == pytest.approx(solid["constrained_viscosity_scale"], rel=1e-9)


def test_the_unfitted_media_are_the_paper_dampers_as_linear_drags():
    # v <- v exp(-c dt) at dt = 2e-4 s: (e^0.16 - 1) / 2e-4 = 867.6 1/s and
    # (e^1.6 - 1) / 2e-4 = 19,765 1/s, so the paper's "10x" medium is 22.8x the source's drag.
    start = fitted.unfitted(0.915)
    assert fitted.damper_drag_rate_per_s(800.0) == pytest.approx(867.55, rel=1e-4)
    assert fitted.damper_drag_rate_per_s(8000.0) == pytest.approx(19765.2, rel=1e-4)
    assert start["constrained_viscosity_scale"] == pytest.approx(22.78, rel=1e-3)
    assert start["medium_drag_ns_per_m2"] == pytest.approx(867.55 * 0.915, rel=1e-4)
    # At the rod's earlier 176.7 us step the same constants gave 20.5x: the ratio depends on dt.
    ratio_177us = fitted.damper_drag_rate_per_s(8000.0, 176.7e-6) / (
        fitted.damper_drag_rate_per_s(800.0, 176.7e-6)
    )
    assert ratio_177us == pytest.approx(20.5, abs=0.05)


def test_fit_cli_writes_only_what_it_is_told(tmp_path, capsys):
    from mjx_arm import constants

    with pytest.raises(SystemExit) as err:
        fit.main([])  # no --out and no --write-model: a usage error before any work
    assert err.value.code == 2
    assert "--write-model" in capsys.readouterr().err
    (tmp_path / "file").write_text("")
    with pytest.raises(SystemExit):
        fit.main(["--out", str(tmp_path / "file" / "fit.json")])
    with pytest.raises(SystemExit):
        fit.main(["--out", str(tmp_path), "--max-iter", "1"])
    model = constants.DEFAULT_MODEL_PATH.read_bytes()
    assert constants.DEFAULT_MODEL_PATH.read_bytes() == model


def test_a_corrupt_fit_file_is_refused_and_a_missing_one_means_unfitted(tmp_path):
    path = tmp_path / "fit.json"
    assert fitted.load_fit(path) is None
    path.write_text(json.dumps({"fitted": {"stiffness_scale": 1.0}}))
    with pytest.raises(ValueError, match="not a fit result"):
        fitted.load_fit(path)
    path.write_text("{not json")
    with pytest.raises(ValueError, match="not a fit result"):
        fitted.load_fit(path)


def test_fidelity_cli_writes_nothing_unless_told(tmp_path, capsys):
    from mjx_arm import fidelity

    with pytest.raises(SystemExit) as err:
        fidelity.main([])
    assert err.value.code == 2 and "--out" in capsys.readouterr().err
    (tmp_path / "file").write_text("")
    with pytest.raises(SystemExit):
        fidelity.main(["--out", str(tmp_path / "file")])


def test_workspace_measures_ranges_and_the_widest_turn():
    from mjx_arm.fidelity import workspace

    rest = np.array([0.0, 0.0, -0.2, 0.0, 0.0, -1.0])
    tilt = np.radians(30.0)
    poses = np.array(
        [
            [0.05, 0.0, -0.19, np.sin(tilt), 0.0, -np.cos(tilt)],
            [-0.03, 0.02, -0.19, -np.sin(tilt), 0.0, -np.cos(tilt)],
            rest,
        ]
    )
    w = workspace(poses, rest)
    assert w["x_range_m"] == pytest.approx(0.08) and w["y_range_m"] == pytest.approx(0.02)
    assert w["max_tilt_rad"] == pytest.approx(tilt)
    assert w["orientation_range_rad"] == pytest.approx(2 * tilt)


def _commands():
    """(module, argv with {out}, the function whose call would be work) of every mjx_arm
    command that writes --out."""
    from mjx_arm import fidelity, model_gen, xcheck

    return [
        (fit, ["--out", "{out}/fit.json", "--max-iter", "1"], "reference_data"),
        (fidelity, ["--out", "{out}"], "run"),
        (xcheck, ["--out", "{out}"], "run"),
        (model_gen, ["--out", "{out}/arm.xml"], "generate_xml"),
    ]


@pytest.mark.parametrize("index", range(4))
@pytest.mark.parametrize("where", ["under_a_file", "read_only"])
def test_every_command_checks_out_before_any_work(index, where, tmp_path, monkeypatch, capsys):
    """--out under a file (cannot be made) or on a read-only mount is a usage error (exit 2),
    before a minute of work (xcheck failed after 121 s). A read-only mount is simulated where
    the write probe happens: root passes every permission bit."""
    from mjx_arm import run_folder

    module, argv, work = _commands()[index]
    monkeypatch.setattr(module, work, lambda *a, **k: pytest.fail(f"{work} ran"))
    (tmp_path / "file").write_text("")
    out = tmp_path / "file" / "sub"
    if where == "read_only":
        out = tmp_path / "ro"

        def read_only(*args, **kwargs):
            raise OSError(30, "Read-only file system")

        monkeypatch.setattr(run_folder.tempfile, "TemporaryFile", read_only)
    with pytest.raises(SystemExit) as stopped:
        module.main([a.format(out=out) for a in argv])
    err = capsys.readouterr().err
    assert stopped.value.code == 2 and "--out" in err, err
    assert ("is not a folder" if where == "under_a_file" else "Read-only") in err, err
    assert not out.exists()


def test_check_out_accepts_a_folder_it_can_make_and_refuses_a_folder_for_a_file(tmp_path):
    import argparse

    from mjx_arm import run_folder

    parser = argparse.ArgumentParser()
    assert run_folder.check_out(parser, "--out", tmp_path / "a" / "b") == tmp_path / "a" / "b"
    assert not (tmp_path / "a").exists()  # checked, not made
    with pytest.raises(SystemExit):
        run_folder.check_out(parser, "--out", tmp_path, file=True)


def test_the_report_computes_the_damper_drags_from_its_results():
    """The figures "867.6 and 19,765 1/s ... 22.8x" come from the results' dampers and step:
    (exp(c dt) - 1) / dt, worked out by hand for c = 800 and 2000 1/s at dt = 2e-4 s."""
    from mjx_arm import constants, fidelity_report

    results = json.loads((constants.ROOT / "results" / "fidelity.json").read_text())
    text = fidelity_report.to_markdown(results)
    assert "a linear drag of 867.6 and 19,765 1/s" in text and "is 22.8x the source's" in text
    results["cosserat"]["damping_per_s"] = {"source": 800.0, "constrained": 2000.0}
    text = fidelity_report.to_markdown(results)
    # exp(0.16) - 1 = 0.17351 -> 867.6 1/s; exp(0.4) - 1 = 0.49182 -> 2,459 1/s; ratio 2.83
    assert "a linear drag of 867.6 and 2,459 1/s" in text, text[:2000]
    assert "is 2.8x the source's, not 2.5x" in text and "19,765" not in text
