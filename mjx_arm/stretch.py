"""Chamber controls that make the chain bend like a stretched Cosserat rod.

The paper's rod (Gazzola's law, `mjx_arm.cosserat`) divides its bending couple by e^3, e the
local stretch: pressurised chambers lengthen the body (all three at 3.5 bar: +37%) and the
thinner, stretched section bends more easily, under gravity and the medium alike. A chain of
constant joint springs cannot do that, so the generated model carries two actuators on every
bending hinge j that the chamber span covers (`mjx_arm.model_gen`):

  * "soften_<joint>", gain affine in the joint angle (gainprm = [0, k_j, 0]), control
    u_j = 1 - 1 / e_j^3: torque k_j q_j u_j, which turns the spring's -k_j q_j into
    -k_j q_j / e_j^3;
  * "unload_<joint>", a motor, control -u_j c_j(p): it scales the chambers' own couple on the
    hinge, c_j(p) (what the chamber tendons put there, linear in the pressures), by 1 / e_j^3.

Together the hinge torque is (c_j(p) - k_j q_j) / e_j^3, the rod's law with the chamber load as
a rest strain (as `mjx_arm.cosserat` and PyElastica write it). The stretch is read from the
pressures: e_j = 1 + w_j s (p0 + p1 + p2), s the axial rest strain per bar (the MJCF's
`<custom>` "stretch_per_bar") and w_j the share of hinge j's rod inside the chamber span (the
actuator's `user` value), which is what the rod's stretch is when no external load pulls it.
Gravity's own stretch (under 1%) and the axial and twist terms of the law are left to the fit.

Everything here is a function of the valve pressures the rollouts already compute every
physics step, so MJX and MuJoCo C run it alike, with no callback: `ChamberControls.numpy`
builds MuJoCo C control arrays, `ChamberControls.jax` sets an MJX data's controls.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_arm import constants


class ChamberControls(NamedTuple):
    """How chamber pressures [3] (bar) become a model's controls [nu]; hashable (tuples).

    Attributes:
      nu: the model's number of actuators.
      chamber_ids: the three chamber actuators (their control is the pressure in bar).
      soften_ids, unload_ids: [J] the hinges' softening and unloading actuators (empty for a
        model without them).
      weights: [J] share w_j of each hinge's rod inside the chamber span (-).
      stretch_per_bar: axial rest strain per bar of summed chamber pressure (1/bar).
      couple_per_bar: [3][J] chamber k's generalised force on hinge j per bar (N m / bar).
    """

    nu: int
    chamber_ids: tuple[int, ...]
    soften_ids: tuple[int, ...] = ()
    unload_ids: tuple[int, ...] = ()
    weights: tuple[float, ...] = ()
    stretch_per_bar: float = 0.0
    couple_per_bar: tuple[tuple[float, ...], ...] = ()

    @property
    def softens(self) -> bool:
        return len(self.soften_ids) > 0

    def hinge_controls(self, pressure_bar, xp=np):
        """(u [..., J], unload [..., J]) for pressures [..., 3] (bar)."""
        pressure = xp.asarray(pressure_bar)
        total = pressure.sum(-1, keepdims=True)
        stretch = 1.0 + xp.asarray(self.weights, pressure.dtype) * self.stretch_per_bar * total
        u = 1.0 - stretch**-3
        couple = pressure @ xp.asarray(self.couple_per_bar, pressure.dtype)
        return u, -u * couple

    def numpy(self, pressure_bar: np.ndarray) -> np.ndarray:
        """MuJoCo C controls [..., nu] (float64) for pressures [..., 3] (bar)."""
        pressure = np.asarray(pressure_bar, dtype=np.float64)
        ctrl = np.zeros(pressure.shape[:-1] + (self.nu,))
        ctrl[..., list(self.chamber_ids)] = pressure
        if self.softens:
            u, unload = self.hinge_controls(pressure)
            ctrl[..., list(self.soften_ids)] = u
            ctrl[..., list(self.unload_ids)] = unload
        return ctrl

    def jax(self, ctrl: jnp.ndarray, pressure_bar: jnp.ndarray) -> jnp.ndarray:
        """An MJX data's controls [nu] with pressures [3] (bar) applied."""
        ctrl = ctrl.at[jnp.asarray(self.chamber_ids)].set(pressure_bar)
        if self.softens:
            u, unload = self.hinge_controls(pressure_bar, xp=jnp)
            ctrl = ctrl.at[jnp.asarray(self.soften_ids)].set(u)
            ctrl = ctrl.at[jnp.asarray(self.unload_ids)].set(unload)
        return ctrl


def from_model(m: mujoco.MjModel) -> ChamberControls:
    """The chamber controls of a compiled model, found by actuator names.

    Raises:
      ValueError: the model has softening actuators without their unloading pair, without a
        `user` weight, or without the "stretch_per_bar" numeric.
    """
    chamber_ids = tuple(int(m.actuator(n).id) for n in constants.CHAMBER_ACTUATORS)
    names = [m.actuator(i).name for i in range(m.nu)]
    soften = [n for n in names if n.startswith(constants.SOFTEN_PREFIX)]
    if not soften:
        return ChamberControls(nu=int(m.nu), chamber_ids=chamber_ids)
    joints = [n[len(constants.SOFTEN_PREFIX) :] for n in soften]
    missing = [j for j in joints if constants.UNLOAD_PREFIX + j not in names]
    if missing:
        raise ValueError(f"softening actuators without their unloading pair: {missing[:4]}")
    if m.nuser_actuator < 1:
        raise ValueError("softening actuators need a user weight (<size nuser_actuator='1'/>)")
    try:
        stretch_per_bar = float(m.numeric(constants.CUSTOM_STRETCH_PER_BAR).data[0])
    except KeyError:
        raise ValueError(
            f"softening actuators need the <custom> numeric {constants.CUSTOM_STRETCH_PER_BAR!r}"
        ) from None
    soften_ids = tuple(int(m.actuator(n).id) for n in soften)
    unload_ids = tuple(int(m.actuator(constants.UNLOAD_PREFIX + j).id) for j in joints)
    weights = tuple(float(m.actuator_user[i, 0]) for i in soften_ids)
    # Each chamber's generalised force per bar on every dof: its tendon's moment arms times its
    # gain (fixed tendons: constant moments, so any state will do).
    data = mujoco.MjData(m)
    mujoco.mj_forward(m, data)
    dofs = [int(m.jnt_dofadr[m.actuator_trnid[i, 0]]) for i in unload_ids]
    couple = []
    for k in chamber_ids:
        couple.append(tuple(float(_moment(m, data, k)[d] * m.actuator_gainprm[k, 0]) for d in dofs))
    return ChamberControls(
        nu=int(m.nu),
        chamber_ids=chamber_ids,
        soften_ids=soften_ids,
        unload_ids=unload_ids,
        weights=weights,
        stretch_per_bar=stretch_per_bar,
        couple_per_bar=tuple(couple),
    )


def _moment(m: mujoco.MjModel, data: mujoco.MjData, actuator: int) -> np.ndarray:
    """Dense moment arms [nv] of one actuator in the current state."""
    moment = np.zeros(m.nv)
    start, count = data.moment_rowadr[actuator], data.moment_rownnz[actuator]
    moment[data.moment_colind[start : start + count]] = data.actuator_moment[start : start + count]
    return moment
