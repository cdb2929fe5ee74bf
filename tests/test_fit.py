"""The fit of the MuJoCo arm to the reference rod: recovers known parameters, stored safely."""

import json

import numpy as np
import pytest

from mjx_arm import fit, fitted
from mjx_arm.fidelity import babble_program


def test_fit_recovers_the_media_of_a_known_arm():
    # Targets from the MuJoCo arm itself at a known drag and constrained scale: the fit, started
    # from the physical values, must find them (stiffness and gain stay at their prior).
    programs = babble_program(7, seconds=6.0, hold_periods=(5, 20))[None]
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
    stored = fitted.load_fit()
    from mjx_arm import CONSTRAINED, ArmParams

    assert ArmParams().stiffness_scale == stored["stiffness_scale"]
    assert ArmParams().medium_drag_ns_per_m2 == stored["medium_drag_ns_per_m2"]
    assert CONSTRAINED.viscosity_scale == stored["constrained_viscosity_scale"]


def test_a_corrupt_fit_file_is_refused_and_a_missing_one_means_unfitted(tmp_path):
    path = tmp_path / "fit.json"
    assert fitted.load_fit(path) == fitted.UNFITTED
    path.write_text(json.dumps({"fitted": {"stiffness_scale": 1.0}}))
    with pytest.raises(ValueError, match="not a fit result"):
        fitted.load_fit(path)
    path.write_text("{not json")
    with pytest.raises(ValueError, match="not a fit result"):
        fitted.load_fit(path)
