"""The rest state every rollout starts from: the arm settled with its chambers at the valve floor.

`mjx_arm.load` settles each arm once; a model with no stable rest is refused there, with the
reason `settle` gives.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjx_arm import constants, stretch
from mjx_arm.constants import MAX_JOINT_SPEED

#: A rest state still moving faster than this (rad/s or m/s) after `settle`'s time is unsettled.
SETTLED_SPEED = 1.0e-3
#: MuJoCo warnings raised when it meets a non-finite or huge state and resets the data.
_INSTABILITY_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)


def settle(
    m: mujoco.MjModel, p_min: float, max_time_s: float = 60.0
) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Rest state: chambers at the valve floor, stepped until the arm stops moving.

    Returns:
      (rest qpos [nq], rest qvel [nv] (zeros), None), or a description of why the model has no
      rest in place of None: it diverged (MuJoCo met a bad state and reset the data, or a speed
      passed MAX_JOINT_SPEED), still moves faster than SETTLED_SPEED after `max_time_s`, or
      rests absurdly far (its tip moved more than twice the arm's length from the reference
      pose; an explicit drag instability can stretch a slide joint by kilometres while every
      number stays finite).
    """
    data = mujoco.MjData(m)
    data.ctrl[:] = stretch.from_model(m).numpy(np.full(3, p_min))
    steps_per_check = max(1, int(0.1 / m.opt.timestep))
    speed = 0.0
    for _ in range(int(max_time_s / 0.1)):
        mujoco.mj_step(m, data, nstep=steps_per_check)
        speed = float(np.abs(data.qvel).max(initial=0.0))
        reset = sum(data.warning[w].number for w in _INSTABILITY_WARNINGS)
        if reset or not np.isfinite(data.qpos).all() or not speed < MAX_JOINT_SPEED:
            return data.qpos.copy(), np.zeros(m.nv), "it diverged while settling"
        if speed < 1e-7:
            break
    if speed > SETTLED_SPEED:
        return (
            data.qpos.copy(),
            np.zeros(m.nv),
            f"it still moves at {speed:.3g} after {max_time_s} s",
        )
    # Tip displacement from the reference pose against the base-to-tip distance there.
    tip_body = m.site_bodyid[m.site(constants.TIP_SITE).id]
    reference = mujoco.MjData(m)
    mujoco.mj_kinematics(m, reference)
    site = m.site(constants.TIP_SITE).id
    length = np.linalg.norm(reference.site_xpos[site] - reference.xpos[m.body_rootid[tip_body]])
    mujoco.mj_kinematics(m, data)
    moved = float(np.linalg.norm(data.site_xpos[site] - reference.site_xpos[site]))
    if moved > 2.0 * length:
        return (
            data.qpos.copy(),
            np.zeros(m.nv),
            f"its tip rests {moved:.3g} m from the reference pose, over twice the arm's length"
            f" ({length:.3g} m)",
        )
    return data.qpos.copy(), np.zeros(m.nv), None
