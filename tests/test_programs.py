"""Tests of mjx_arm.programs: the five test shapes and the shape-like programs (pure numpy)."""

import numpy as np
import pytest

from mjx_arm import programs


@pytest.mark.parametrize("name", list(programs.SHAPES))
def test_shape_programs_in_valve_range(name):
    p = programs.SHAPES[name](60.0)
    assert p.shape == (600, 3)
    assert np.isfinite(p).all()
    assert p.min() >= programs.P_LOW_BAR and p.max() <= programs.P_HIGH_BAR
    # Every shape moves: each chamber swings by at least 1 bar.
    assert (np.ptp(p, axis=0) > 1.0).all()


@pytest.mark.parametrize("name", programs.PERIODIC_SHAPES)
def test_periodic_shapes_repeat_every_30_s(name):
    p = programs.SHAPES[name](60.0)
    np.testing.assert_allclose(p[:300], p[300:], atol=1e-9)
    assert not np.allclose(p[:150], p[150:300])  # ...and not with half the period


def test_circle_is_three_phased_sinusoids():
    p = programs.circle(60.0)
    t = np.arange(600) / 10.0
    expected0 = programs.P_MID_BAR + programs.AMPLITUDE_BAR * np.sin(2 * np.pi * t / 30.0)
    np.testing.assert_allclose(p[:, 0], expected0, atol=1e-12)
    # Chamber 1 lags chamber 0 by 120 deg = 10 s = 100 steps.
    np.testing.assert_allclose(p[100:, 1], p[:-100, 0], atol=1e-9)
    # Phases 0/120/240: the mean pressure is constant (pure bending).
    np.testing.assert_allclose(p.mean(axis=1), programs.P_MID_BAR, atol=1e-9)


def test_damped_circle_shrinks():
    p = programs.damped_circle(60.0)
    assert np.ptp(p[-300:], axis=0).max() < 0.6 * np.ptp(p[:300], axis=0).max()


def test_shape_like_programs_in_range_reproducible_and_never_a_test_shape():
    p = programs.shape_like_programs(64, 60.0, seed=3, split="train")
    assert p.shape == (64, 600, 3) and p.dtype == np.float32 and np.isfinite(p).all()
    lo, hi = (
        programs.P_MID_BAR - programs.AMPLITUDE_BAR,
        programs.P_MID_BAR + programs.AMPLITUDE_BAR,
    )
    assert p.min() >= lo - 1e-5 and p.max() <= hi + 1e-5
    # Program i does not depend on how many are drawn; other seeds and splits differ.
    np.testing.assert_array_equal(programs.shape_like_programs(5, 60.0, seed=3)[:], p[:5])
    assert not np.allclose(programs.shape_like_programs(5, 60.0, seed=4), p[:5])
    assert not np.allclose(programs.shape_like_programs(5, 60.0, seed=3, split="val"), p[:5])
    # Every program moves, and at least one is a staircase (holds for >= 5 steps at a time)
    # and one is smooth (changes at every step).
    assert (np.ptp(p, axis=1).max(axis=-1) > 0.05).all()
    changes = np.abs(np.diff(p, axis=1)).max(axis=-1) > 1e-6  # [64, 599]
    assert (changes.mean(axis=1) < 0.2).any() and changes.all(axis=1).any()
    # Some add a common-mode offset (the mean pressure leaves P_MID), some do not.
    mean_offset = np.abs(p.mean(axis=2) - programs.P_MID_BAR).max(axis=1)
    assert (mean_offset > 0.1).any() and (mean_offset < 1e-4).any()
    # None is one of the five test programs.
    for fn in programs.SHAPES.values():
        assert np.abs(p - fn(60.0)[None]).max(axis=(1, 2)).min() > 0.1
    # Full scale: the same draws scaled up to the amplitude limit, still in range.
    full = programs.shape_like_programs(64, 60.0, seed=3, split="train", full_scale=True)
    assert full.min() >= lo - 1e-5 and full.max() <= hi + 1e-5
    peak, peak_full = (np.abs(x - programs.P_MID_BAR).max(axis=(1, 2)) for x in (p, full))
    assert (peak_full >= peak - 1e-5).all() and (peak_full > peak + 0.1).mean() > 0.3
