"""Calibrate the source domain's fluid viscosity to the paper's step response.

The paper's simulator (PyElastica, translational damping 800 1/s) reaches 63% of its final tip
deflection about 0.25 s after a step couple (`paper-facts.md`). This command finds the medium's
drag per length (N s/m^2, `ArmParams.medium_drag_ns_per_m2`) whose mechanical step response,
a pressure step on chamber 0 with the valve bypassed, has the same 63% time, by bisection on
MuJoCo C rollouts. It then reports the mechanical 63% times of both domains.

    python -m mjx_arm.calibrate            # prints the fitted drag for ArmParams
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import mujoco
import numpy as np

from mjx_arm import arm as arm_lib
from mjx_arm import constants, domains
from mjx_arm.model_gen import ArmParams, generate_xml

TARGET_T63_S = 0.25


def mechanical_t63(params: ArmParams, domain: domains.Domain, duration_s: float = 4.0) -> float:
    """63% time (s) of the tip deflection after a valve-less 3.5 bar step on chamber 0."""
    m = mujoco.MjModel.from_xml_string(generate_xml(params))
    domains.apply(m, domain)
    mujoco.mj_setConst(m, mujoco.MjData(m))
    qpos, _ = arm_lib._settle(m, constants.P_MIN_BAR)
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    tip = m.site(constants.TIP_SITE).id
    mujoco.mj_kinematics(m, d)
    rest = d.site_xpos[tip].copy()
    ids = [m.actuator(n).id for n in constants.CHAMBER_ACTUATORS]
    d.ctrl[ids] = [constants.P_MAX_BAR, constants.P_MIN_BAR, constants.P_MIN_BAR]
    n = int(round(duration_s / m.opt.timestep))
    deflection = np.zeros(n)
    for k in range(n):
        mujoco.mj_step(m, d)
        deflection[k] = np.linalg.norm(d.site_xpos[tip] - rest)
    times = m.opt.timestep * np.arange(n)  # site_xpos lags the state by one step
    return arm_lib.time_constant_63(times, deflection)


def fit_drag(params: ArmParams, target_s: float = TARGET_T63_S, tolerance_s: float = 2e-3) -> float:
    """Bisects the source drag (N s/m^2) until the mechanical 63% time is within tolerance."""
    low, high = 10.0, 1.0e5
    for _ in range(30):
        mid = math.sqrt(low * high)
        t63 = mechanical_t63(dataclasses.replace(params, medium_drag_ns_per_m2=mid), domains.SOURCE)
        if abs(t63 - target_s) < tolerance_s:
            return mid
        low, high = (mid, high) if t63 < target_s else (low, mid)
    return mid


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="Fit the source viscosity to the paper.")
    parser.add_argument("--target", type=float, default=TARGET_T63_S, help="63%% time (s)")
    parser.add_argument("--segments", type=int, default=None, help="segment count to fit")
    args = parser.parse_args(argv)
    params = ArmParams()
    params = dataclasses.replace(params, n_segments=args.segments or params.n_segments)
    drag = fit_drag(params, args.target)
    fitted = dataclasses.replace(params, medium_drag_ns_per_m2=drag)
    print(
        f"{params.n_segments} segments: fitted source drag {drag:.0f} N s/m^2 (ArmParams has"
        f" {params.medium_drag_ns_per_m2:.0f}), viscosity {fitted.viscosity_pa_s:.2f} Pa s"
    )
    for domain in (domains.SOURCE, domains.CONSTRAINED):
        t_mech = mechanical_t63(fitted, domain, duration_s=4.0 if domain is domains.SOURCE else 20)
        print(f"  {domain.name:12s} mechanical 63% time {t_mech:.3f} s")


if __name__ == "__main__":
    main()
