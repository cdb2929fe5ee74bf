"""How closely the MuJoCo arm follows the reference Cosserat rod, in both domains.

For the committed model and for 5- and 20-segment chains generated from the same `ArmParams`,
against `mjx_arm.cosserat` with 20 elements and the paper's damping constants (800 1/s source,
8000 1/s constrained):

  * statics: tip position error per chamber at 1, 2 and 3.5 bar (others at the 0.2 bar floor);
  * step response: time to 63.2% of the final tip deflection after chamber 0 steps to 2 bar,
    with the valve and without it (a step of the chamber force: the mechanics alone);
  * babbling: tip position RMS error and d3 angle error over 60 s of seeded pseudo-random
    pressures (random targets held for random durations).

The committed model's stiffness, chamber gain and media were fitted to the same rod by
`python -m mjx_arm.fit` on other babbling programs (seeds 100-102, holds of 0.5-10 s); every
number here is on held-out programs.
The 5- and 20-segment chains reuse the 10-segment fit (drag per length, viscosity scale).

Run `python -m mjx_arm.fidelity`; it writes results/fidelity.md and results/fidelity.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

import mjx_arm
from mjx_arm import constants, cosserat, valve
from mjx_arm.arm import time_constant_63
from mjx_arm.machine import cpu_model
from mjx_arm.model_gen import ArmParams, generate_xml

STATIC_PRESSURES_BAR = (1.0, 2.0, 3.5)
STEP_PRESSURE_BAR = 2.0
#: Hold times (s) of the step responses: long enough for the slowest model to settle.
STEP_HOLD_S = {"source": 6.0, "constrained": 30.0}
#: Hold time (s) of the static poses in MuJoCo (the rod is solved for equilibrium directly).
STATIC_HOLD_S = {"source": 10.0, "constrained": 40.0}
BABBLE_SECONDS = 60.0
BABBLE_SEEDS = (0, 1, 2)
#: Babbling holds each random target for 0.5 to 3 s (5 to 30 control periods).
BABBLE_HOLD_PERIODS = (5, 30)
VARIANTS = ("committed", 5, 20)
DOMAINS = ("source", "constrained")
NO_VALVE = valve.ValveParams(tau_rise_s=1e-9, tau_drop_s=1e-9)


def babble_program(
    seed: int, seconds: float = BABBLE_SECONDS, hold_periods: tuple[int, int] = BABBLE_HOLD_PERIODS
) -> np.ndarray:
    """Pseudo-random commands [T, 3] (bar) at 10 Hz: uniform targets in [0.2, 3.5] bar per
    chamber, all three held together for a random number of control periods in `hold_periods`
    (default 0.5-3 s), then redrawn."""
    rng = np.random.default_rng(seed)
    n_periods = int(round(seconds * constants.CONTROL_HZ))
    program = np.empty((n_periods, 3))
    t = 0
    while t < n_periods:
        hold = int(rng.integers(hold_periods[0], hold_periods[1] + 1))
        program[t : t + hold] = rng.uniform(constants.P_MIN_BAR, constants.P_MAX_BAR, 3)
        t += hold
    return program


def load_arm(variant, domain: str) -> mjx_arm.Arm:
    """The committed model or an `n_segments` chain from the generator, in `domain`."""
    if variant == "committed":
        return mjx_arm.load(domain=domain)
    xml = generate_xml(dataclasses.replace(ArmParams(), n_segments=int(variant)))
    return mjx_arm.load(xml=xml, domain=domain)


def static_commands() -> tuple[np.ndarray, list[tuple[int, float]]]:
    """Commands [9, 3] (bar): each chamber alone at each static pressure, with their labels."""
    labels = [(k, p) for k in range(3) for p in STATIC_PRESSURES_BAR]
    commands = np.full((len(labels), 3), constants.P_MIN_BAR)
    for i, (k, p) in enumerate(labels):
        commands[i, k] = p
    return commands, labels


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) between unit vectors [..., 3]."""
    cos = np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)
    return np.arccos(cos)


# ---------------------------------------------------------------------- dense step responses


def _valve_pressures(command: np.ndarray, n_periods: int, n_sub: int, dt: float, vp) -> np.ndarray:
    """Per-substep pressures [n_periods * n_sub, 3] for a command held from the floor."""
    pressure = np.full(3, constants.P_MIN_BAR)
    out = []
    for _ in range(n_periods):
        sub = np.asarray(
            valve.substep_pressures(jnp.asarray(pressure), jnp.asarray(command), n_sub, dt, vp)
        )
        out.append(sub)
        pressure = sub[-1]
    return np.concatenate(out)


def mujoco_step_response(arm: mjx_arm.Arm, hold_s: float, use_valve: bool) -> tuple:
    """Times (s) and tip xy deflection (m) every physics step after chamber 0 steps to 2 bar."""
    m = arm.mj_model
    data = mujoco.MjData(m)
    data.qpos[:], data.qvel[:] = arm.rest_qpos, arm.rest_qvel
    mujoco.mj_forward(m, data)
    rest_xy = data.site_xpos[arm.tip_site_id][:2].copy()
    command = np.array([STEP_PRESSURE_BAR, constants.P_MIN_BAR, constants.P_MIN_BAR])
    n_periods = int(round(hold_s * constants.CONTROL_HZ))
    pressures = _valve_pressures(
        command, n_periods, arm.n_substeps, arm.timestep_s, arm.valve if use_valve else NO_VALVE
    )
    deflection = np.empty(len(pressures))
    for i, p in enumerate(pressures):
        data.ctrl[arm.actuator_ids] = p
        mujoco.mj_step(m, data)
        deflection[i] = np.linalg.norm(data.site_xpos[arm.tip_site_id][:2] - rest_xy)
    times = arm.timestep_s * np.arange(1, len(pressures) + 1)
    return times, deflection


@functools.lru_cache(maxsize=8)
def _cosserat_dense_fn(params: cosserat.CosseratParams):
    rod = cosserat._make_rod(params)
    zero = jnp.zeros(3)

    def run(rest, pressures):
        def body(st, p):
            st = cosserat._step(rod, st, p, zero, zero, rod.trans_damp, rod.rot_damp)
            return st, st.x[-1, :2]

        return jax.lax.scan(body, rest, pressures)[1]

    return jax.jit(run)


def cosserat_step_response(params: cosserat.CosseratParams, hold_s: float, use_valve: bool):
    """As `mujoco_step_response`, for the rod (sampled every physics step)."""
    rest = cosserat.rest_state(params)
    command = np.array([STEP_PRESSURE_BAR, constants.P_MIN_BAR, constants.P_MIN_BAR])
    n_periods = int(round(hold_s * constants.CONTROL_HZ))
    pressures = _valve_pressures(
        command,
        n_periods,
        params.n_substeps,
        params.timestep_s,
        valve.ValveParams() if use_valve else NO_VALVE,
    )
    with jax.enable_x64(True):
        xy = _cosserat_dense_fn(params)(
            cosserat.RodState(*(jnp.asarray(a, jnp.float64) for a in rest)),
            jnp.asarray(pressures, jnp.float64),
        )
        xy = np.asarray(xy)
    deflection = np.linalg.norm(xy - rest.x[-1, :2], axis=-1)
    times = params.timestep_s * np.arange(1, len(pressures) + 1)
    return times, deflection


def _t63(times, deflection) -> float:
    return time_constant_63(times, deflection)


def paper_geometry_t63() -> dict:
    """Mechanical 63% times (s) of the rod with the paper code's geometry (0.19 m, 1104 kg/m^3),
    to compare with PyElastica's measured 0.25 s (c = 800) and 5.3 s (c = 8000)."""
    length = 0.19
    mass = 1104.0 * math.pi * ArmParams().radius_m ** 2 * length
    out = {"length_m": length, "mass_kg": mass}
    for domain, hold in (("source", 4.0), ("constrained", 40.0)):
        params = cosserat.CosseratParams.for_domain(domain, length_m=length, mass_kg=mass)
        out[domain] = _t63(*cosserat_step_response(params, hold, use_valve=False))
    return out


# ---------------------------------------------------------------------- the comparison


def rod_reference(domain: str, n_elements: int) -> dict:
    """Everything the comparison needs from the rod in one domain."""
    params = cosserat.CosseratParams.for_domain(domain, n_elements=n_elements)
    t0 = time.perf_counter()
    commands, _ = static_commands()
    statics = np.stack([cosserat.static_pose(c, params) for c in commands])
    rest = cosserat.static_pose(np.full(3, constants.P_MIN_BAR), params)
    steps = {
        name: _t63(*cosserat_step_response(params, STEP_HOLD_S[domain], use_valve))
        for name, use_valve in (("valve", True), ("no_valve", False))
    }
    programs = np.stack([babble_program(s) for s in BABBLE_SEEDS])
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


def compare(variant, domain: str, ref: dict) -> dict:
    """Errors of one MuJoCo model in one domain against the rod's reference."""
    arm = load_arm(variant, domain)
    length = ArmParams().length_m
    commands, labels = static_commands()
    hold = int(round(STATIC_HOLD_S[domain] * constants.CONTROL_HZ))
    held = arm.rollout(np.repeat(commands[:, None], hold, axis=1), backend="c")
    mj_statics = held[:, -1]
    drift = np.linalg.norm(held[:, -1, :3] - held[:, -11, :3], axis=-1).max()
    static_err = np.linalg.norm(mj_statics[:, :3] - ref["statics"][:, :3], axis=-1)
    static_angle = angle_between(mj_statics[:, 3:], ref["statics"][:, 3:])
    rod_deflection = np.linalg.norm(ref["statics"][:, :2] - ref["rest"][:2], axis=-1)
    mj_rest = arm.rest_pose()
    mj_deflection = np.linalg.norm(mj_statics[:, :2] - mj_rest[:2], axis=-1)

    t63 = {
        name: _t63(*mujoco_step_response(arm, STEP_HOLD_S[domain], use_valve))
        for name, use_valve in (("valve", True), ("no_valve", False))
    }

    t0 = time.perf_counter()
    babble = arm.rollout(ref["programs"], backend="c")
    babble_wall = time.perf_counter() - t0
    pos_err = np.linalg.norm(babble[..., :3] - ref["babble"][..., :3], axis=-1)
    ang_err = angle_between(babble[..., 3:], ref["babble"][..., 3:])
    rod_motion = np.linalg.norm(ref["babble"][..., :3] - ref["rest"][:3], axis=-1)
    return {
        "model": "committed (10 segments)" if variant == "committed" else f"{variant} segments",
        "n_segments": int(arm.mj_model.nbody - 1),
        "domain": domain,
        "rest_tip_error_m": float(np.linalg.norm(mj_rest[:3] - ref["rest"][:3])),
        "static": [
            {
                "chamber": k,
                "pressure_bar": p,
                "tip_error_m": float(e),
                "tip_error_pct_length": float(100 * e / length),
                "d3_error_rad": float(a),
                "deflection_rod_m": float(dr),
                "deflection_mujoco_m": float(dm),
            }
            for (k, p), e, a, dr, dm in zip(
                labels, static_err, static_angle, rod_deflection, mj_deflection, strict=True
            )
        ],
        "static_drift_last_second_m": float(drift),
        "t63_s": {"mujoco": t63, "cosserat": ref["t63"]},
        "babble": {
            "tip_rms_error_m": float(np.sqrt(np.mean(pos_err**2))),
            "tip_rms_error_pct_length": float(100 * np.sqrt(np.mean(pos_err**2)) / length),
            "tip_max_error_m": float(pos_err.max()),
            "d3_mean_error_rad": float(ang_err.mean()),
            "d3_max_error_rad": float(ang_err.max()),
            "rod_tip_rms_motion_m": float(np.sqrt(np.mean(rod_motion**2))),
            "mujoco_c_sim_s_per_wall_s": float(
                babble.shape[0] * babble.shape[1] / 10 / babble_wall
            ),
            "mujoco_c_threads": int(min(os.cpu_count() or 1, babble.shape[0])),
        },
    }


def run(n_elements: int = 20) -> dict:
    """Runs the whole comparison; returns the JSON-ready results."""
    t0 = time.perf_counter()
    rows = []
    refs = {}
    for domain in DOMAINS:
        refs[domain] = rod_reference(domain, n_elements)
        print(f"rod reference, {domain}: {refs[domain]['seconds']:.1f} s", flush=True)
        for variant in VARIANTS:
            rows.append(compare(variant, domain, refs[domain]))
            print(f"  compared {rows[-1]['model']}", flush=True)
    params = refs["source"]["params"]
    paper = paper_geometry_t63()
    return {
        "command": "python -m mjx_arm.fidelity",
        "cpu": cpu_model(),
        "wall_s": time.perf_counter() - t0,
        "arm_length_m": ArmParams().length_m,
        "cosserat": {
            "n_elements": params.n_elements,
            "timestep_s": params.timestep_s,
            "damping_per_s": {d: refs[d]["params"].damping_per_s for d in DOMAINS},
            "rotational_damping": params.rotational_damping,
            "mass_kg": params.mass_kg,
            "shear_coefficient": params.shear_coefficient,
            "rest_pose": refs["source"]["rest"].tolist(),
            "paper_geometry_t63_s": paper,
        },
        "protocol": {
            "static_pressures_bar": STATIC_PRESSURES_BAR,
            "static_hold_s": STATIC_HOLD_S,
            "step_pressure_bar": STEP_PRESSURE_BAR,
            "step_hold_s": STEP_HOLD_S,
            "babble_seconds": BABBLE_SECONDS,
            "babble_seeds": BABBLE_SEEDS,
            "babble_hold_periods": BABBLE_HOLD_PERIODS,
        },
        "rows": rows,
    }


def to_markdown(results: dict) -> str:
    """A readable report of `run()`'s results."""
    length = results["arm_length_m"]
    c = results["cosserat"]
    lines = [
        "# MuJoCo arm vs reference Cosserat rod",
        "",
        f"Produced by `{results['command']}` on {results['cpu']} in {results['wall_s']:.0f} s.",
        "",
        f"Reference: `mjx_arm.cosserat`, {c['n_elements']} elements, timestep"
        f" {c['timestep_s'] * 1e6:.1f} us, translational damping {c['damping_per_s']['source']:g}"
        f" 1/s (source) and {c['damping_per_s']['constrained']:g} 1/s (constrained), rotational"
        f" {c['rotational_damping']:g}. Same geometry, material, chamber forces and valves as"
        " the MuJoCo model, except the rod's density: the paper code's 1104 kg/m^3"
        f" ({c['mass_kg']:.3f} kg), so the per-mass damping constants are the paper's media;"
        " the MuJoCo arm keeps the paper's 183 g. The committed model's stiffness, chamber gain"
        " and media were fitted to this rod by `python -m mjx_arm.fit` (models/softarm_fit.json)"
        " on other babbling programs; everything below is held out. Errors are absolute and as"
        f" % of the arm length ({length * 100:g} cm).",
        "",
        "Check of the rod's dynamics against PyElastica: with the paper code's geometry"
        f" ({c['paper_geometry_t63_s']['length_m']:g} m, {c['paper_geometry_t63_s']['mass_kg']:.3f}"
        " kg) a step of chamber 0's force reaches 63% after"
        f" {c['paper_geometry_t63_s']['source']:.3f} s (c = 800) and"
        f" {c['paper_geometry_t63_s']['constrained']:.2f} s (c = 8000); PyElastica 1.0 measured"
        " about 0.25 s and 5.3 s (shared/notes/paper-facts.md). The reference below is 0.2 m"
        " long, hence its slightly slower times.",
        "",
        "## Statics: each chamber alone, others at the 0.2 bar floor",
        "",
        "Tip error = |p_mujoco - p_rod|; deflection = tip xy distance from each model's own rest"
        " pose; each row is the worst of the three chambers (they agree to 0.01 mm, see the"
        " JSON). MuJoCo held each command for the protocol's hold time; statics do not depend"
        " on the domain.",
        "",
        "| model | domain | bar | tip error mm | % L | d3 error mrad | rod deflection mm |"
        " MuJoCo deflection mm |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in results["rows"]:
        for pressure in results["protocol"]["static_pressures_bar"]:
            same = [s for s in row["static"] if s["pressure_bar"] == pressure]
            worst = max(same, key=lambda s: s["tip_error_m"])
            lines.append(
                f"| {row['model']} | {row['domain']} | {pressure:g} |"
                f" {worst['tip_error_m'] * 1e3:.2f} | {worst['tip_error_pct_length']:.2f} |"
                f" {max(s['d3_error_rad'] for s in same) * 1e3:.1f} |"
                f" {worst['deflection_rod_m'] * 1e3:.2f} |"
                f" {worst['deflection_mujoco_m'] * 1e3:.2f} |"
            )
    lines += [
        "",
        "| model | domain | rest tip error mm | MuJoCo static drift over last second mm |",
        "|---|---|---|---|",
    ]
    for row in results["rows"]:
        lines.append(
            f"| {row['model']} | {row['domain']} | {row['rest_tip_error_m'] * 1e3:.3f} |"
            f" {row['static_drift_last_second_m'] * 1e3:.4f} |"
        )
    lines += [
        "",
        f"## Step response: chamber 0 from 0.2 to {results['protocol']['step_pressure_bar']:g} bar",
        "",
        "Time to 63.2% of the final tip deflection, sampled every physics step. 'valve': the"
        " command steps and the valve lags (tau rise 0.2 s); 'no valve': the chamber force"
        " steps (the mechanics alone).",
        "",
        "| model | domain | MuJoCo valve s | rod valve s | MuJoCo no valve s | rod no valve s |",
        "|---|---|---|---|---|---|",
    ]
    for row in results["rows"]:
        t = row["t63_s"]
        lines.append(
            f"| {row['model']} | {row['domain']} | {t['mujoco']['valve']:.3f} |"
            f" {t['cosserat']['valve']:.3f} | {t['mujoco']['no_valve']:.3f} |"
            f" {t['cosserat']['no_valve']:.3f} |"
        )
    p = results["protocol"]
    lines += [
        "",
        f"## Babbling: {p['babble_seconds']:g} s x {len(p['babble_seeds'])} seeds",
        "",
        "Targets uniform in [0.2, 3.5] bar per chamber, held together for"
        f" {p['babble_hold_periods'][0]}-{p['babble_hold_periods'][1]} control periods; poses"
        " compared at every 10 Hz sample. 'rod motion' is the RMS tip distance from rest in the"
        " rod, for scale. 'MuJoCo C sim s/s': simulated seconds per wall second of these"
        " rollouts (`mujoco.rollout`, one thread per trajectory, this CPU): the speed side of"
        " the segment-count trade-off (MJX on a GPU: bench/results).",
        "",
        "| model | domain | tip RMS error mm | % L | tip max error mm | d3 mean error mrad |"
        " d3 max error mrad | rod motion RMS mm | MuJoCo C sim s/s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in results["rows"]:
        b = row["babble"]
        lines.append(
            f"| {row['model']} | {row['domain']} | {b['tip_rms_error_m'] * 1e3:.2f} |"
            f" {b['tip_rms_error_pct_length']:.2f} | {b['tip_max_error_m'] * 1e3:.2f} |"
            f" {b['d3_mean_error_rad'] * 1e3:.1f} | {b['d3_max_error_rad'] * 1e3:.1f} |"
            f" {b['rod_tip_rms_motion_m'] * 1e3:.2f} | {b['mujoco_c_sim_s_per_wall_s']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=constants.ROOT / "results")
    parser.add_argument("--elements", type=int, default=20, help="Cosserat elements")
    args = parser.parse_args(argv)
    results = run(args.elements)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "fidelity.json").write_text(json.dumps(results, indent=2, default=_jsonable))
    (args.out / "fidelity.md").write_text(to_markdown(results))
    print(f"wrote {args.out / 'fidelity.md'} and fidelity.json ({results['wall_s']:.0f} s)")
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
