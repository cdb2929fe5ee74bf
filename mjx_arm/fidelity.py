"""How closely the MuJoCo arm follows the reference Cosserat rod, and what regime it is in.

For 10-, 20- and 30-segment chains generated from `ArmParams` (10 is the committed model), against
`mjx_arm.cosserat` with the same section and mass, 20 elements, the paper code's damping
(800 1/s source, 8000 1/s constrained) and its 2e-4 s step:

  * statics: tip position error per chamber at 1, 2 and 3.5 bar (others at the 0.2 bar floor);
  * step response: time to 63.2% of the final tip deflection after chamber 0 steps to 2 bar,
    with the valve and without it (a step of the chamber force: the mechanics alone);
  * babbling: tip position RMS error and d3 angle error over 60 s of seeded pseudo-random
    pressures (random targets held for random durations), against the limits the model must
    meet: tip RMS at most 3% of the length and 10% of the rod's RMS tip excursion, statics
    within 1% of the length, 63% times within 10%;
  * the regime: tip displacement and bend angle per chamber, elongation with all three at
    3.5 bar, the babbling workspace (tip x/y range, tilt and orientation range);
  * stability: full-range (bang-bang 0 / 3.5 bar) babbling on MuJoCo C with MuJoCo's warnings
    counted, and MJX (on this CPU) against MuJoCo C on the same programs.

The committed model's media were fitted to the same rod by `python -m mjx_arm.fit` on other
babbling programs (seeds 100-102, holds of 0.5-30 s); every number here is on held-out programs.
The 20- and 30-segment chains reuse the 10-segment fit (drag per length, viscosity scale).

Run `python -m mjx_arm.fidelity --out results` to regenerate the committed report
(results/fidelity.md and .json); `--out` is required, so no run writes into the repository unless
told to.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path

import mujoco
import numpy as np
from tqdm import tqdm

import mjx_arm
from mjx_arm import constants, cosserat, fidelity_report, fidelity_shapes, run_folder, valve
from mjx_arm.arm import time_constant_63
from mjx_arm.machine import cpu_model, usable_cores
from mjx_arm.model_gen import ArmParams, generate_xml
from mjx_arm.programs import full_range_program, held_program

STATIC_PRESSURES_BAR = (1.0, 2.0, 3.5)
STEP_PRESSURE_BAR = 2.0
#: Hold times (s) of the step responses: long enough for the slowest model to settle (the
#: constrained 63% time is about 26 s).
STEP_HOLD_S = {"source": 15.0, "constrained": 150.0}
#: Hold time (s) of the static poses in MuJoCo (the rod is solved for equilibrium directly):
#: over 10 time constants of the slowest pose, the stretched, softened arm in the constrained
#: medium (its 63% time is about 35 s at 2 bar and twice that with 1 / e^3 = 0.47 at the common
#: mode; 200 s left 8 mm of that pose unsettled).
STATIC_HOLD_S = {"source": 20.0, "constrained": 800.0}
BABBLE_SECONDS = 60.0
BABBLE_SEEDS = (0, 1, 2)
#: Babbling holds each random target for 0.5 to 3 s (5 to 30 control periods).
BABBLE_HOLD_PERIODS = (5, 30)
#: Chain lengths compared (segments); the committed model's count must be among them.
SEGMENTS = (10, 20, 30)
DOMAINS = ("source", "constrained")
NO_VALVE = valve.ValveParams(tau_rise_s=1e-9, tau_drop_s=1e-9)
#: What the committed model must meet on held-out programs (issue "the arm at the paper's scale").
LIMITS = {
    "tip_rms_pct_length": 3.0,
    "tip_rms_pct_excursion": 10.0,
    "static_error_pct_length": 1.0,
    "t63_error_pct": 10.0,
}
#: Full-range stability programs: seeds, and holds of 0.1-1 s between the valve's two ends.
STABILITY_SEEDS = (10, 11, 12, 13)
STABILITY_HOLD_PERIODS = (1, 10)


def chain_xml(n_segments: int) -> str:
    """MJCF text of the `n_segments` chain with the committed fit."""
    return generate_xml(dataclasses.replace(ArmParams(), n_segments=n_segments))


def constant_springs_xml() -> str | None:
    """MJCF text of the 10-segment chain without stretch softening, with its own refit
    (`CONSTANT_SPRINGS_FIT`), or None when that file is missing."""
    if not CONSTANT_SPRINGS_FIT.exists():
        return None
    fitted_values = json.loads(CONSTANT_SPRINGS_FIT.read_text())["fitted"]
    return generate_xml(dataclasses.replace(ArmParams(), stretch_softening=False, **fitted_values))


#: The common-mode static command: chamber 0 2 bar above the others, all raised to the valve's
#: top (3.5 / 1.5 / 1.5 bar): the body stretches 28% and, under the paper's law, bends less
#: under gravity's pull than chamber 0 at 2 bar alone.
COMMON_MODE_BAR = (3.5, 1.5, 1.5)
#: A constant-spring chain refitted to the same rod (`python -m mjx_arm.fit --constant-springs`),
#: compared beside the committed model.
CONSTANT_SPRINGS_FIT = constants.ROOT / "results" / "fit_constant_springs.json"


def static_commands() -> tuple[np.ndarray, list[tuple[int, float]]]:
    """Commands [11, 3] (bar): each chamber alone at each static pressure, all three at 3.5 bar
    (chamber label -1), then the common-mode command (label -2), with their labels."""
    labels = [(k, p) for k in range(3) for p in STATIC_PRESSURES_BAR]
    labels += [(-1, constants.P_MAX_BAR), (-2, COMMON_MODE_BAR[0])]
    commands = np.full((len(labels), 3), constants.P_MIN_BAR)
    for i, (k, p) in enumerate(labels):
        if k == -2:
            commands[i] = COMMON_MODE_BAR
        elif k < 0:
            commands[i] = p
        else:
            commands[i, k] = p
    return commands, labels


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) between unit vectors [..., 3]."""
    cos = np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)
    return np.arccos(cos)


def valve_pressures(command: np.ndarray, hold_s: float, dt_s: float, use_valve: bool):
    """Per-physics-step chamber pressures [N, 3] (bar) for `command` held from the valve floor."""
    params = valve.ValveParams() if use_valve else NO_VALVE
    n_periods = int(round(hold_s * constants.CONTROL_HZ))
    n_sub = int(round(constants.CONTROL_PERIOD_S / dt_s))
    pressure = np.full(3, constants.P_MIN_BAR)
    out = []
    for _ in range(n_periods):
        sub = np.asarray(valve.substep_pressures(pressure, command, n_sub, dt_s, params))
        out.append(sub)
        pressure = sub[-1]
    return np.concatenate(out)


STEP_COMMAND = np.array([STEP_PRESSURE_BAR, constants.P_MIN_BAR, constants.P_MIN_BAR])


def mujoco_t63(arm: mjx_arm.Arm, hold_s: float, use_valve: bool) -> float:
    """63% time (s) of the tip's xy deflection after chamber 0 steps to 2 bar, every step."""
    m = arm.mj_model
    data = mujoco.MjData(m)
    data.qpos[:], data.qvel[:] = arm.rest_qpos, arm.rest_qvel
    mujoco.mj_forward(m, data)
    rest_xy = data.site_xpos[arm.tip_site_id][:2].copy()
    pressures = valve_pressures(STEP_COMMAND, hold_s, arm.timestep_s, use_valve)
    deflection = np.empty(len(pressures))
    for i, p in enumerate(pressures):
        data.ctrl[:] = arm.chamber_controls.numpy(p)
        mujoco.mj_step(m, data)
        deflection[i] = np.linalg.norm(data.site_xpos[arm.tip_site_id][:2] - rest_xy)
    return time_constant_63(arm.timestep_s * np.arange(1, len(pressures) + 1), deflection)


def rod_t63(params: cosserat.CosseratParams, hold_s: float, use_valve: bool) -> float:
    """As `mujoco_t63`, for the rod."""
    pressures = valve_pressures(STEP_COMMAND, hold_s, params.timestep_s, use_valve)
    tips = cosserat.tip_each_step(pressures, params)
    rest = cosserat.rest_state(params).x[-1]
    deflection = np.linalg.norm(tips[:, :2] - rest[:2], axis=-1)
    return time_constant_63(params.timestep_s * np.arange(1, len(pressures) + 1), deflection)


def workspace(poses: np.ndarray, rest: np.ndarray) -> dict:
    """Tip x/y ranges (m), largest tilt of d3 from its rest direction and the largest angle
    between any two d3 samples (rad) of poses [..., 6]."""
    flat = poses.reshape(-1, 6)
    d3 = flat[:, 3:]
    spread = float(np.arccos(np.clip(d3 @ d3.T, -1.0, 1.0)).max())
    return {
        "x_range_m": float(np.ptp(flat[:, 0])),
        "y_range_m": float(np.ptp(flat[:, 1])),
        "max_tilt_rad": float(angle_between(d3, rest[3:]).max()),
        "orientation_range_rad": spread,
    }


# ---------------------------------------------------------------------- the comparison


def rod_reference(domain: str, n_elements: int) -> dict:
    """Everything the comparison needs from the rod in one domain."""
    params = cosserat.CosseratParams.from_arm(ArmParams(), domain, n_elements=n_elements)
    t0 = time.perf_counter()
    commands, _ = static_commands()
    statics = np.stack([cosserat.static_pose(c, params) for c in commands])
    rest = cosserat.static_pose(np.full(3, constants.P_MIN_BAR), params)
    steps = {
        name: rod_t63(params, STEP_HOLD_S[domain], use_valve)
        for name, use_valve in (("valve", True), ("no_valve", False))
    }
    programs = np.stack(
        [held_program(s, BABBLE_SECONDS, BABBLE_HOLD_PERIODS) for s in BABBLE_SEEDS]
    )
    babble = cosserat.rollout(programs, params)
    return {
        "params": params,
        "rest": rest,
        "statics": statics,
        "t63": steps,
        "babble": babble,
        "programs": programs,
        "seconds": time.perf_counter() - t0,
    }


def static_rows(statics: np.ndarray, rest: np.ndarray, ref: dict) -> list[dict]:
    """Per static command: tip displacement and bend angle from rest, both models, and the
    error against the rod."""
    _, labels = static_commands()
    length = ArmParams().length_m
    rows = []
    for i, (k, p) in enumerate(labels):
        error = float(np.linalg.norm(statics[i, :3] - ref["statics"][i, :3]))
        rows.append(
            {
                "chamber": k,
                "pressure_bar": p,
                "tip_error_m": error,
                "tip_error_pct_length": 100 * error / length,
                "d3_error_rad": float(angle_between(statics[i, 3:], ref["statics"][i, 3:])),
                "displacement_rod_m": float(
                    np.linalg.norm(ref["statics"][i, :3] - ref["rest"][:3])
                ),
                "displacement_mujoco_m": float(np.linalg.norm(statics[i, :3] - rest[:3])),
                "bend_rod_rad": float(angle_between(ref["statics"][i, 3:], ref["rest"][3:])),
                "bend_mujoco_rad": float(angle_between(statics[i, 3:], rest[3:])),
                "elongation_rod_m": float(ref["rest"][2] - ref["statics"][i, 2]),
                "elongation_mujoco_m": float(rest[2] - statics[i, 2]),
            }
        )
    return rows


def compare(
    n_segments: int, domain: str, ref: dict, xml: str | None = None, label: str = ""
) -> dict:
    """Errors of one chain in one domain against the rod's reference (`xml`: another chain
    than the committed fit's, named by `label`)."""
    arm = mjx_arm.load(xml=xml or chain_xml(n_segments), domain=domain)
    length = ArmParams().length_m
    commands, _ = static_commands()
    hold = int(round(STATIC_HOLD_S[domain] * constants.CONTROL_HZ))
    held = arm.rollout(np.repeat(commands[:, None], hold, axis=1), backend="c")
    drift = np.linalg.norm(held[:, -1, :3] - held[:, -11, :3], axis=-1).max()
    mj_rest = arm.rest_pose()
    t63 = {
        name: mujoco_t63(arm, STEP_HOLD_S[domain], use_valve)
        for name, use_valve in (("valve", True), ("no_valve", False))
    }
    t0 = time.perf_counter()
    babble = arm.rollout(ref["programs"], backend="c")
    babble_wall = time.perf_counter() - t0
    pos_err = np.linalg.norm(babble[..., :3] - ref["babble"][..., :3], axis=-1)
    ang_err = angle_between(babble[..., 3:], ref["babble"][..., 3:])
    rod_motion = np.linalg.norm(ref["babble"][..., :3] - ref["rest"][:3], axis=-1)
    rms = float(np.sqrt(np.mean(pos_err**2)))
    motion_rms = float(np.sqrt(np.mean(rod_motion**2)))
    return {
        "model": label or f"{n_segments} segments" + (" (committed)" if n_segments == 10 else ""),
        "variant": label or None,
        "n_segments": n_segments,
        "domain": domain,
        "inertia_scale": arm.inertia_scale,
        "rest_tip_error_m": float(np.linalg.norm(mj_rest[:3] - ref["rest"][:3])),
        "static": static_rows(held[:, -1], mj_rest, ref),
        "static_drift_last_second_m": float(drift),
        "t63_s": {"mujoco": t63, "cosserat": ref["t63"]},
        "babble": {
            "tip_rms_error_m": rms,
            "tip_rms_error_pct_length": 100 * rms / length,
            "tip_rms_error_pct_excursion": 100 * rms / motion_rms,
            "tip_max_error_m": float(pos_err.max()),
            "d3_mean_error_rad": float(ang_err.mean()),
            "d3_max_error_rad": float(ang_err.max()),
            "rod_tip_rms_excursion_m": motion_rms,
            "workspace_rod": workspace(ref["babble"], ref["rest"]),
            "workspace_mujoco": workspace(babble, mj_rest),
            "mujoco_c_sim_s_per_wall_s": float(
                babble.shape[0] * babble.shape[1] / constants.CONTROL_HZ / babble_wall
            ),
            "mujoco_c_threads": int(min(usable_cores(), babble.shape[0])),
        },
    }


def verdict(row: dict) -> dict:
    """Which of `LIMITS` one committed-model row meets (True/False per limit)."""
    t = row["t63_s"]
    t63_err = max(abs(t["mujoco"][k] / t["cosserat"][k] - 1.0) * 100 for k in ("valve", "no_valve"))
    b = row["babble"]
    return {
        "tip_rms_pct_length": b["tip_rms_error_pct_length"] <= LIMITS["tip_rms_pct_length"],
        "tip_rms_pct_excursion": b["tip_rms_error_pct_excursion"]
        <= LIMITS["tip_rms_pct_excursion"],
        "static_error_pct_length": max(s["tip_error_pct_length"] for s in row["static"])
        <= LIMITS["static_error_pct_length"],
        "t63_error_pct": t63_err <= LIMITS["t63_error_pct"],
        "t63_error_pct_value": t63_err,
    }


def stability(n_segments: int) -> dict:
    """Full-range programs on MuJoCo C (rollouts and a stepped loop counting MuJoCo's warnings)
    and on MJX (this machine's JAX backend), per domain."""
    programs = np.stack(
        [full_range_program(s, BABBLE_SECONDS, STABILITY_HOLD_PERIODS) for s in STABILITY_SEEDS]
    )
    out = {}
    for domain in DOMAINS:
        arm = mjx_arm.load(xml=chain_xml(n_segments), domain=domain)
        poses_c = arm.rollout(programs, backend="c")  # raises SimulationDivergedError if any does
        m = arm.mj_model
        data = mujoco.MjData(m)
        data.qpos[:] = arm.rest_qpos
        for command in programs[0]:
            data.ctrl[:] = arm.chamber_controls.numpy(command)
            mujoco.mj_step(m, data, nstep=arm.n_substeps)
        warnings = {
            mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(data.warning) if w.number
        }
        t0 = time.perf_counter()
        poses_mjx = arm.rollout(programs[:1], backend="mjx")
        mjx_wall = time.perf_counter() - t0
        diff = np.linalg.norm(poses_mjx[..., :3] - poses_c[:1, :, :3], axis=-1)
        out[domain] = {
            "programs": len(programs),
            "seconds": BABBLE_SECONDS,
            "finite": bool(np.isfinite(poses_c).all()),
            "mujoco_warnings": warnings,
            "mjx_vs_c_max_tip_m": float(diff.max()),
            "mjx_vs_c_max_d3": float(np.abs(poses_mjx[..., 3:] - poses_c[:1, :, 3:]).max()),
            "mjx_wall_s_with_compile": mjx_wall,
            "tip_range_m": float(np.ptp(poses_c[..., :2])),
        }
    return out


def solid_comparison(path: Path) -> dict | None:
    """The earlier solid-disc arm's committed numbers (`results/fidelity_solid.json`)."""
    if not path.exists():
        return None
    old = json.loads(path.read_text())
    rows = {(r["domain"], r["n_segments"]): r for r in old["rows"]}
    src, con = rows[("source", 10)], rows[("constrained", 10)]
    deflection = {
        s["pressure_bar"]: s["deflection_rod_m"] for s in src["static"] if s["chamber"] == 0
    }
    return {
        "rod_deflection_m": deflection,
        "rod_babble_tip_rms_motion_m": {
            "source": src["babble"]["rod_tip_rms_motion_m"],
            "constrained": con["babble"]["rod_tip_rms_motion_m"],
        },
        "rod_t63_no_valve_s": {
            "source": src["t63_s"]["cosserat"]["no_valve"],
            "constrained": con["t63_s"]["cosserat"]["no_valve"],
        },
        "chain_babble_tip_rms_error_m": {
            "source": src["babble"]["tip_rms_error_m"],
            "constrained": con["babble"]["tip_rms_error_m"],
        },
    }


def run(n_elements: int = 20, segments=SEGMENTS, solid_path: Path | None = None) -> dict:
    """Runs the whole comparison; returns the JSON-ready results."""
    t0 = time.perf_counter()
    rows = []
    refs = {}
    jobs = [(d, n) for d in DOMAINS for n in segments]
    constant = constant_springs_xml()
    extra = len(DOMAINS) if constant else 0
    with tqdm(total=len(DOMAINS) + len(jobs) + extra + 1, desc="fidelity", unit="job") as bar:
        for domain in DOMAINS:
            bar.set_postfix_str(f"rod, {domain}")
            refs[domain] = rod_reference(domain, n_elements)
            bar.update()
            for n in segments:
                bar.set_postfix_str(f"{n} segments, {domain}")
                rows.append(compare(n, domain, refs[domain]))
                bar.update()
            if constant:
                bar.set_postfix_str(f"constant springs, {domain}")
                label = "10 segments, constant springs (refit)"
                rows.append(compare(10, domain, refs[domain], xml=constant, label=label))
                bar.update()
        bar.set_postfix_str("stability")
        stable = stability(10)
        bar.update()
    params = refs["source"]["params"]
    committed = [r for r in rows if r["n_segments"] == 10 and not r["variant"]]
    solid_path = solid_path or constants.ROOT / "results" / "fidelity_solid.json"
    return {
        "command": "python -m mjx_arm.fidelity --out results",
        "cpu": cpu_model(),
        "cpu_cores": os.cpu_count(),
        "wall_s": time.perf_counter() - t0,
        "arm": {
            "section": ArmParams().section,
            "length_m": ArmParams().length_m,
            "mass_kg": ArmParams().mass_kg,
            "youngs_modulus_pa": ArmParams().youngs_modulus_pa,
            "second_moment_m4": ArmParams().second_moment_m4,
            "area_m2": ArmParams().area_m2,
        },
        "cosserat": {
            "n_elements": params.n_elements,
            "timestep_s": params.timestep_s,
            "damping_per_s": {d: refs[d]["params"].damping_per_s for d in DOMAINS},
            "rotational_damping": params.rotational_damping,
            "mass_kg": params.mass_kg,
            "shear_coefficient": params.shear_coefficient,
            "law": params.law,
            "rest_pose": refs["source"]["rest"].tolist(),
        },
        "protocol": {
            "static_pressures_bar": STATIC_PRESSURES_BAR,
            "static_hold_s": STATIC_HOLD_S,
            "step_pressure_bar": STEP_PRESSURE_BAR,
            "step_hold_s": STEP_HOLD_S,
            "babble_seconds": BABBLE_SECONDS,
            "babble_seeds": BABBLE_SEEDS,
            "babble_hold_periods": BABBLE_HOLD_PERIODS,
            "stability_seeds": STABILITY_SEEDS,
            "stability_hold_periods": STABILITY_HOLD_PERIODS,
        },
        "limits": LIMITS,
        "verdict": {r["domain"]: verdict(r) for r in committed},
        "rows": rows,
        "stability": stable,
        "solid": solid_comparison(solid_path),
        "shapes": fidelity_shapes.shape_comparison(log=tqdm.write),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m mjx_arm.fidelity",
        description=__doc__.splitlines()[0].rstrip(".")
        + ". Writes fidelity.md and .json into --out (the committed report: --out results).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--out", type=Path, required=True, help="folder for the report")
    parser.add_argument("--elements", type=int, default=20, help="Cosserat elements")
    parser.add_argument(
        "--only",
        choices=["shapes"],
        help="recompute only this section into the fidelity.json already in --out (shapes: the"
        " five shapes' programs, chain against rod; about 30 s instead of the report's 15 min)",
    )
    args = parser.parse_args(argv)
    if args.elements < 2:
        parser.error("--elements must be >= 2")
    run_folder.check_out(parser, "--out", args.out)
    if args.only:
        stored = args.out / "fidelity.json"
        if not stored.is_file():
            parser.error(
                f"--only {args.only} updates {stored}, which does not exist: run without it"
            )
        results = json.loads(stored.read_text())
        results["shapes"] = fidelity_shapes.shape_comparison()
    else:
        results = run(args.elements)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "fidelity.json").write_text(json.dumps(results, indent=2, default=_jsonable))
    (args.out / "fidelity.md").write_text(fidelity_report.to_markdown(results))
    what = f"the {args.only} section" if args.only else f"{results['wall_s']:.0f} s"
    print(f"wrote {args.out / 'fidelity.md'} and fidelity.json ({what})")
    return 0


def _jsonable(value):
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if dataclasses.is_dataclass(value):
        return dataclasses.asdict(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    raise TypeError(f"cannot serialise {type(value)}")


if __name__ == "__main__":
    sys.exit(main())
