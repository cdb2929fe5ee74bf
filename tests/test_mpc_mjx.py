"""Tests of tracking.mpc_mjx (the one-step tracker in MJX) against tracking.mpc (MuJoCo C), on
a 3-segment arm."""

import numpy as np
import pytest

import mjx_arm
from mjx_arm.programs import circle, kite
from tracking import held, metrics, mpc, mpc_mjx


@pytest.fixture(scope="module")
def arms():
    """(D_s, D_c) 3-segment solid-disc arms, as tests/test_tracking_mpc.py's."""
    xml = mjx_arm.generate_xml(mjx_arm.ArmParams(section="solid", n_segments=3))
    return mjx_arm.load(xml=xml, domain="source"), mjx_arm.load(xml=xml, domain="constrained")


def test_mjx_tracker_plans_as_the_c_tracker(arms, monkeypatch):
    arm_s, arm_c = arms
    announced = []
    monkeypatch.setattr(mpc_mjx, "announce_compile", lambda *a, **kw: announced.append(a[1:3]))
    k = 3
    programs = np.stack([circle(0.7), kite(0.7)])
    targets = arm_s.rollout(programs, backend="c")
    cfg = mpc.MpcConfig(horizon_steps=1, iterations=1)
    want, want_info = mpc.track(arm_c, targets, k, programs, cfg)
    # Chunks of 3 steps: the 7 steps end inside a padded chunk.
    got, info = mpc_mjx.track(arm_c, targets, k, programs, cfg, chunk_steps=3)
    assert announced == [(2, 3)]  # the compile is announced once, with its batch and chunk
    assert got.shape == want.shape == (2, 7 * k, 3) and info["healthy"].all()
    blocks = got.reshape(2, 7, k, 3)
    np.testing.assert_array_equal(blocks, np.repeat(blocks[:, :, :1], k, axis=2))
    assert got.min() >= arm_c.valve.p_min_bar and got.max() <= arm_c.valve.p_max_bar
    # float32 MJX against float64 C. Two chambers sit at a valve limit here and the cost is flat
    # along the third (0.1-0.2 bar apart at equal cost to 4 digits), so the tracking and the
    # cost are compared, not the commands; at the first step, before the arm is pushed to the
    # limits, the plans agree.
    np.testing.assert_allclose(got[:, 0], want[:, 0], atol=0.02)
    err = {
        name: metrics.position_error_cm(held.run_dc(arm_c, c, k, "c"), targets).mean()
        for name, c in (("mjx", got), ("c", want))
    }
    stretched = held.stretch(programs, k)
    err_stretch = metrics.position_error_cm(held.run_dc(arm_c, stretched, k, "c"), targets).mean()
    assert err["mjx"] < 0.95 * err_stretch
    assert abs(err["mjx"] - err["c"]) < 0.005 * err["c"]
    # The reported cost is the applied step's squared residual in MJX; C agrees closely.
    np.testing.assert_allclose(info["cost"], want_info["cost"], rtol=0.02, atol=1e-5)


def test_mjx_tracker_refuses_what_it_cannot_plan(arms):
    _, arm_c = arms
    with pytest.raises(ValueError, match="one step at a time"):
        mpc_mjx.track(arm_c, np.zeros((5, 6)), 2, np.zeros((5, 3)), mpc.MpcConfig(horizon_steps=2))
    with pytest.raises(ValueError, match="do not match"):
        mpc_mjx.track(arm_c, np.zeros((5, 6)), 2, np.zeros((4, 3)))
    with pytest.raises(ValueError, match="chunk_steps"):
        mpc_mjx.track(arm_c, np.zeros((5, 6)), 2, np.zeros((5, 3)), chunk_steps=0)


def test_mjx_tracker_stopped_goes_on_where_it_stopped(arms, tmp_path):
    """A run stopped between chunks keeps the simulator states and plans in its resume file; the
    next run with the same programs goes on from there and plans what one whole run plans."""
    arm_s, arm_c = arms
    k, cfg = 3, mpc.MpcConfig(horizon_steps=1, iterations=1)
    programs = np.stack([circle(0.7), kite(0.7)])
    targets = arm_s.rollout(programs, backend="c")
    whole, _ = mpc_mjx.track(arm_c, targets, k, programs, cfg, chunk_steps=3)
    resume, logs = tmp_path / "partial.npz", []
    run = dict(cfg=cfg, chunk_steps=3, resume=resume, log=logs.append)
    with pytest.raises(mpc_mjx.TrackingStopped, match="after 3 of 7"):
        mpc_mjx.track(arm_c, targets, k, programs, should_stop=lambda: True, **run)
    assert resume.exists() and not logs
    with pytest.raises(mpc_mjx.TrackingStopped, match="after 6 of 7"):
        mpc_mjx.track(arm_c, targets, k, programs, should_stop=lambda: True, **run)
    assert logs == [f"resuming from {resume}: 3 of 7 source steps done"]
    got, info = mpc_mjx.track(arm_c, targets, k, programs, **run)
    assert info["resumed_steps"] == 6 and info["healthy"].all() and not resume.exists()
    np.testing.assert_array_equal(got, whole)
    # Progress saved for other programs is not used.
    with pytest.raises(mpc_mjx.TrackingStopped):
        mpc_mjx.track(arm_c, targets[::-1], k, programs[::-1], should_stop=lambda: True, **run)
    logs.clear()
    got, info = mpc_mjx.track(arm_c, targets, k, programs, **run)
    assert info["resumed_steps"] == 0 and "saved for other programs" in logs[0]
    np.testing.assert_array_equal(got, whole)


def test_a_resume_file_of_another_medium_does_not_match():
    """Two domains share the MJCF's hash: the resume fingerprint must tell them apart, or a
    teacher_partial.npz planned in the aged arm would be resumed for D_c."""
    from types import SimpleNamespace

    from mjx_arm import domains

    cfg = mpc.MpcConfig(horizon_steps=2)
    init, target = np.zeros((1, 4, 3)), np.zeros((1, 4, 6))
    arm_c = SimpleNamespace(model_hash="same", domain=domains.CONSTRAINED)
    arm_a = SimpleNamespace(model_hash="same", domain=domains.AGED)
    key_c = mpc_mjx._fingerprint(arm_c, 2, cfg, init, target, 3)
    assert key_c == mpc_mjx._fingerprint(arm_c, 2, cfg, init, target, 3)
    assert key_c != mpc_mjx._fingerprint(arm_a, 2, cfg, init, target, 3)
    # The MuJoCo C tracker's cache (eval's mpc_commands.npz) tells them apart the same way.
    key_c = mpc._fingerprint(arm_c, target, init, 3, cfg)
    assert key_c == mpc._fingerprint(arm_c, target, init, 3, cfg)
    assert key_c != mpc._fingerprint(arm_a, target, init, 3, cfg)
