"""The reference rod side by side with PyElastica 1.0, the paper simulator's library.

PyElastica (`pip install -e ".[xcheck]"`) builds the same rod: the arm's section (A, I, J of
`mjx_arm.section`, not a solid disc), mass, material, 20 elements, the paper code's damper
(v <- v exp(-c dt), omega <- omega exp(-c_rot dt m_e / J)^e) at its 2e-4 s step, gravity, the
valves of `mjx_arm.valve`, and each chamber's load written as PyElastica's rest strains
(sigma0 = F / EA e3 along the chamber span, kappa0 = -F (d3 x r) / B on its Voronoi domains),
updated every physics step from the valve pressures.

The clamp is the one difference in construction. PyElastica's `OneEndFixedBC` freezes the first
element, which moves the clamp half an element up; `mjx_arm.cosserat` clamps a fixed frame at the
base node with a half-length Voronoi domain before the first element. To compare like with like,
the PyElastica rod here has a 21st element of 1 micron at the base, held fixed
(`FixedConstraint` on its two nodes and its directors): its Voronoi domain with the first real
element is then half an element long, the reference rod's clamp.

Compared (`run`): statics with one chamber at 1, 2 and 3.5 bar, common-mode pressure (1.3 bar
added to every chamber on top of a 2 bar difference, with gravity, where the stretch factors
show), step responses of chamber 0 to 2 bar in both domains, and held-out 60 s programs of
random held targets (seeds 200-201, never used by the fit or the fidelity report) in both
domains. Each comparison is given for both of the reference rod's laws; PyElastica always has
the stretch factors, so the "linear" column shows what leaving them out costs.

Run `python -m mjx_arm.xcheck --out results` for results/xcheck_pyelastica.md and .json.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from mjx_arm import atomic, constants, cosserat, run_folder, valve
from mjx_arm.arm import time_constant_63
from mjx_arm.machine import cpu_model
from mjx_arm.programs import held_program

#: Length of the fixed base element that gives PyElastica the reference rod's clamp (m).
CLAMP_ELEMENT_M = 1e-6
#: Single-chamber static pressures (bar), as `mjx_arm.fidelity`.
STATIC_PRESSURES_BAR = (1.0, 2.0, 3.5)
#: Common mode: chamber 0 at 2 bar above the others, then 1.3 bar added to all three (the most
#: the valve range allows).
COMMON_MODE_BAR = ((2.2, 0.2, 0.2), (3.5, 1.5, 1.5))
#: Step response of chamber 0 to 2 bar, held long enough for each domain to settle (s).
STEP_HOLD_S = {"source": 12.0, "constrained": 120.0}
#: Held-out programs (seeds never used by `mjx_arm.fit` or `mjx_arm.fidelity`).
PROGRAM_SEEDS = (200, 201)
PROGRAM_SECONDS = 60.0
PROGRAM_HOLD_PERIODS = (5, 30)
#: Held time and damping rate (1/s) of PyElastica's static solves (the rod's settle rate).
SETTLE_S = 2.0
#: The target the issue sets: every static and step-response difference within 1% of L.
LIMIT_PCT_LENGTH = 1.0


def _elastica():
    try:
        import elastica
    except ImportError as err:  # an optional extra
        raise ImportError(
            "the PyElastica cross-check needs the [xcheck] extra: pip install -e '.[xcheck]'"
        ) from err
    return elastica


class ElasticaArm:
    """The reference rod's twin in PyElastica, stepped one physics step at a time.

    Args:
      params: the reference rod (`law` is ignored: PyElastica always divides by the stretch).
      damping_per_s: translational damper constant c (1/s); `params.damping_per_s` if None.
      rotational_damping: rotational constant c_rot; `params.rotational_damping` if None.
    """

    def __init__(
        self,
        params: cosserat.CosseratParams,
        damping_per_s: float | None = None,
        rotational_damping: float | None = None,
    ):
        ea = _elastica()
        self.params = params
        p, n = params, params.n_elements
        ell, dt = p.element_length_m, p.timestep_s
        self.dt = dt

        class Simulator(
            ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping, ea.CallBacks
        ):
            pass

        self.simulator = Simulator()
        z = -np.concatenate([[0.0], CLAMP_ELEMENT_M + ell * np.arange(n + 1)])
        position = np.stack([np.zeros(n + 2), np.zeros(n + 2), z])
        radius = math.sqrt(p.area_m2 / math.pi)
        rod = ea.CosseratRod.straight_rod(
            n + 1,
            np.zeros(3),
            np.array([0.0, 0.0, -1.0]),
            np.array([1.0, 0.0, 0.0]),
            p.length_m + CLAMP_ELEMENT_M,
            radius,
            p.density_kg_m3,
            youngs_modulus=p.youngs_modulus_pa,
            shear_modulus=p.shear_modulus_pa,
            position=position,
        )
        # The section is the arm's (three tubes), not PyElastica's solid disc of that area.
        shear = np.diag([p.shear_stiffness_n, p.shear_stiffness_n, p.axial_stiffness_n])
        bend = np.diag(
            [p.bend_stiffness_nm2, p.bend_stiffness_nm2, p.shear_modulus_pa * p.polar_moment_m4]
        )
        rod.shear_matrix[:] = shear[:, :, None]
        rod.bend_matrix[:] = bend[:, :, None]
        lengths = rod.rest_lengths
        mass = p.density_kg_m3 * p.area_m2 * lengths
        per_mass = np.array([p.second_moment_m4, p.second_moment_m4, p.polar_moment_m4]) / p.area_m2
        rod.mass_second_moment_of_inertia[:] = 0.0
        rod.inv_mass_second_moment_of_inertia[:] = 0.0
        for k in range(3):
            rod.mass_second_moment_of_inertia[k, k] = mass * per_mass[k]
            rod.inv_mass_second_moment_of_inertia[k, k] = 1.0 / (mass * per_mass[k])
        rod.mass[:] = 0.0
        rod.mass[:-1] += 0.5 * mass
        rod.mass[1:] += 0.5 * mass
        self.rod = rod
        self.simulator.append(rod)
        self.simulator.constrain(rod).using(
            ea.FixedConstraint, constrained_position_idx=(0, 1), constrained_director_idx=(0,)
        )
        if p.gravity_mps2:
            self.simulator.add_forcing_to(rod).using(
                ea.GravityForces, acc_gravity=np.array([0.0, 0.0, -p.gravity_mps2])
            )
        c = p.damping_per_s if damping_per_s is None else damping_per_s
        c_rot = p.rotational_damping if rotational_damping is None else rotational_damping
        trans = math.exp(-c * dt)
        rot = np.exp(-c_rot * dt * mass / (mass * per_mass[:, None]))  # [3, n + 1]

        class PaperDamper(ea.DamperBase):
            """The paper code's damper: v <- v exp(-c dt), omega <- omega rot^e."""

            def dampen_rates(self, system, time):
                system.velocity_collection *= trans
                system.omega_collection *= np.power(rot, system.dilatation)

        self.simulator.dampen(rod).using(PaperDamper)
        self.simulator.finalize()
        self.stepper = ea.PositionVerlet()
        self.time = 0.0

        # Chamber loads as rest strains: element fractions (the frozen one gets none) and
        # Voronoi fractions, the first Voronoi being the reference rod's base half-domain.
        starts = np.arange(n) * ell

        def overlap(lo, hi):
            return np.clip(np.minimum(hi, p.chamber_length_m) - np.maximum(lo, 0.0), 0.0, None)

        self.elem_frac = np.concatenate([[0.0], overlap(starts, starts + ell) / ell])
        vor_lo = np.concatenate([[0.0], starts[1:] - 0.5 * ell])
        vor_hi = np.concatenate([[0.5 * ell], starts[1:] + 0.5 * ell])
        self.vor_frac = overlap(vor_lo, vor_hi) / (vor_hi - vor_lo)
        angles = 2.0 * np.pi * np.arange(3) / 3.0
        offsets = p.chamber_offset_m * np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], -1)
        clamp = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
        self.couple_dir = np.cross(np.array([0.0, 0.0, 1.0]), offsets @ clamp.T)  # [3, 3] local
        self.force_per_bar = constants.BAR_TO_PA * p.chamber_area_m2
        self.bend_diag = np.diag(bend)

    def set_pressures(self, pressure_bar: np.ndarray) -> None:
        """Writes the chamber loads of pressures [3] (bar) as rest strains."""
        force = np.asarray(pressure_bar) * self.force_per_bar
        self.rod.rest_sigma[2] = force.sum() * self.elem_frac / self.params.axial_stiffness_n
        active = self.vor_frac[None, :] * (force @ self.couple_dir)[:, None]  # [3, n]
        self.rod.rest_kappa[:] = -active / self.bend_diag[:, None]

    def step(self, pressure_bar: np.ndarray) -> None:
        self.set_pressures(pressure_bar)
        self.time = self.stepper.step(self.simulator, self.time, self.dt)

    def pose(self) -> np.ndarray:
        """Tip pose [6]: tip node (m) then d3 of the last element."""
        return np.concatenate(
            [self.rod.position_collection[:, -1], self.rod.director_collection[2, :, -1]]
        )

    def tip(self) -> np.ndarray:
        return self.rod.position_collection[:, -1].copy()

    def finite(self) -> bool:
        return bool(np.isfinite(self.rod.position_collection).all())


def _settle(
    params: cosserat.CosseratParams, pressure_bar: np.ndarray, start: ElasticaArm | None = None
) -> ElasticaArm:
    """PyElastica held at `pressure_bar` under the reference rod's static-solve damping."""
    rate = params.settle_rate_per_s
    arm = start or ElasticaArm(params, damping_per_s=rate, rotational_damping=0.0)
    for _ in range(int(round(SETTLE_S / arm.dt))):
        arm.step(pressure_bar)
    return arm


def elastica_static_poses(params: cosserat.CosseratParams, commands: np.ndarray) -> np.ndarray:
    """Equilibrium poses [N, 6] under pressures [N, 3] (bar), each settled from the rest state
    of the previous (statics have no history, so the order only saves time)."""
    poses = []
    rod = None
    for command in commands:
        rod = _settle(params, command, rod)
        poses.append(rod.pose())
    return np.stack(poses)


def elastica_rollout(
    params: cosserat.CosseratParams, commands: np.ndarray, progress: tqdm | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Commands [T, 3] (bar) from rest -> (poses [T, 6] at the end of each period, tip [T * n_sub,
    3] after every physics step). Rest: settled at the valve floor with gravity."""
    static = _settle(params, np.full(3, constants.P_MIN_BAR))
    arm = ElasticaArm(params)
    for name in (
        "position_collection",
        "director_collection",
        "velocity_collection",
        "omega_collection",
    ):
        getattr(arm.rod, name)[:] = getattr(static.rod, name)
    arm.rod.velocity_collection[:] = 0.0
    arm.rod.omega_collection[:] = 0.0
    n_sub = params.n_substeps
    commands = np.asarray(valve.saturate(commands, valve.ValveParams()))
    pressure = np.full(3, constants.P_MIN_BAR)
    poses, tips = [], []
    for command in commands:
        sub = np.asarray(
            valve.substep_pressures(
                pressure, command, n_sub, params.timestep_s, valve.ValveParams()
            )
        )
        for p in sub:
            arm.step(p)
            tips.append(arm.tip())
        pressure = sub[-1]
        poses.append(arm.pose())
        if progress is not None:
            progress.update(1)
    if not arm.finite():
        raise RuntimeError("PyElastica's rod diverged")
    return np.stack(poses), np.stack(tips)


# ---------------------------------------------------------------------- the comparison


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0))


def _step_pressures(params: cosserat.CosseratParams, hold_s: float) -> np.ndarray:
    """Per-physics-step valve pressures [N, 3] (bar) of chamber 0 stepping to 2 bar from rest."""
    command = np.array([2.0, constants.P_MIN_BAR, constants.P_MIN_BAR])
    n_sub = params.n_substeps
    pressure = np.full(3, constants.P_MIN_BAR)
    out = []
    for _ in range(int(round(hold_s * constants.CONTROL_HZ))):
        sub = np.asarray(
            valve.substep_pressures(
                pressure, command, n_sub, params.timestep_s, valve.ValveParams()
            )
        )
        out.append(sub)
        pressure = sub[-1]
    return np.concatenate(out)


def _t63(params: cosserat.CosseratParams, tips: np.ndarray, rest: np.ndarray) -> float:
    deflection = np.linalg.norm(tips[:, :2] - rest[:2], axis=-1)
    return time_constant_63(params.timestep_s * np.arange(1, len(tips) + 1), deflection)


def run(
    n_elements: int = 20, program_seconds: float = PROGRAM_SECONDS, seeds=PROGRAM_SEEDS
) -> dict:
    """Every comparison of the module docstring; figures in m, s and % of the rod's length."""
    t_start = time.perf_counter()
    base = cosserat.CosseratParams(n_elements=n_elements)
    length = base.length_m
    laws = cosserat.LAWS
    results: dict = {"n_elements": n_elements, "laws": list(laws), "length_m": length}

    # Statics: chamber 0 alone, then the common-mode pair (gravity on; the medium is irrelevant).
    commands = np.full((len(STATIC_PRESSURES_BAR), 3), constants.P_MIN_BAR)
    commands[:, 0] = STATIC_PRESSURES_BAR
    commands = np.concatenate(
        [np.full((1, 3), constants.P_MIN_BAR), commands, np.array(COMMON_MODE_BAR)]
    )
    elastica = elastica_static_poses(base, commands)
    ours = {
        law: np.stack(
            [cosserat.static_pose(c, dataclasses.replace(base, law=law)) for c in commands]
        )
        for law in laws
    }

    def lateral_mm(poses):
        return [1e3 * float(np.linalg.norm(poses[i, :2] - poses[0, :2])) for i in (1, 2, 3)]

    def bend_deg(poses, i):
        return float(np.degrees(_angle(poses[i, 3:], np.array([0.0, 0.0, -1.0]))))

    statics = {
        "pressures_bar": list(STATIC_PRESSURES_BAR),
        "lateral_tip_mm": {},
        "error_pct_length": {},
    }
    common = {
        "commands_bar": [list(c) for c in COMMON_MODE_BAR],
        "bend_deg": {},
        "bend_drop_deg": {},
    }
    for name, poses in [("pyelastica", elastica)] + [(f"rod_{law}", ours[law]) for law in laws]:
        statics["lateral_tip_mm"][name] = lateral_mm(poses)
        bends = [bend_deg(poses, 4), bend_deg(poses, 5)]
        common["bend_deg"][name] = bends
        common["bend_drop_deg"][name] = bends[0] - bends[1]
    for law in laws:
        err = np.linalg.norm(ours[law][:, :3] - elastica[:, :3], axis=-1)
        statics["error_pct_length"][f"rod_{law}"] = (100 * err / length).tolist()
    results["statics"] = statics
    results["common_mode"] = common

    # Step responses and held-out programs, per domain.
    programs = np.stack([held_program(s, program_seconds, PROGRAM_HOLD_PERIODS) for s in seeds])
    n_periods = sum(int(round(STEP_HOLD_S[d] * constants.CONTROL_HZ)) for d in STEP_HOLD_S)
    total = n_periods + 2 * programs.shape[0] * programs.shape[1]
    bar = tqdm(total=total, desc="PyElastica", unit="period", mininterval=5)
    for domain in ("source", "constrained"):
        params = cosserat.CosseratParams.for_domain(domain, n_elements=n_elements)
        step_cmds = np.tile(
            [2.0, constants.P_MIN_BAR, constants.P_MIN_BAR],
            (int(round(STEP_HOLD_S[domain] * constants.CONTROL_HZ)), 1),
        )
        rest_el = elastica_static_poses(params, np.full((1, 3), constants.P_MIN_BAR))[0]
        _, el_tips = elastica_rollout(params, step_cmds, bar)
        pressures = _step_pressures(params, STEP_HOLD_S[domain])
        step = {"t63_s": {"pyelastica": _t63(params, el_tips, rest_el)}, "max_error_pct_length": {}}
        for law in laws:
            p_law = dataclasses.replace(params, law=law)
            tips = cosserat.tip_each_step(pressures, p_law)
            step["t63_s"][f"rod_{law}"] = _t63(p_law, tips, cosserat.rest_state(p_law).x[-1])
            err = np.linalg.norm(tips - el_tips, axis=-1)
            step["max_error_pct_length"][f"rod_{law}"] = float(100 * err.max() / length)
        el_poses = np.stack([elastica_rollout(params, prog, bar)[0] for prog in programs])
        excursion = float(np.sqrt(np.mean(np.sum((el_poses[..., :3] - rest_el[:3]) ** 2, -1))))
        prog = {
            "seeds": list(seeds),
            "seconds": program_seconds,
            "pyelastica_tip_rms_excursion_m": excursion,
            "workspace_xy_m": {"pyelastica": np.ptp(el_poses[..., :2].reshape(-1, 2), 0).tolist()},
            "tip_rms_pct_length": {},
            "tip_rms_pct_excursion": {},
            "d3_mean_error_rad": {},
        }
        for law in laws:
            poses = cosserat.rollout(programs, dataclasses.replace(params, law=law))
            err = np.linalg.norm(poses[..., :3] - el_poses[..., :3], axis=-1)
            rms = float(np.sqrt(np.mean(err**2)))
            prog["tip_rms_pct_length"][f"rod_{law}"] = 100 * rms / length
            prog["tip_rms_pct_excursion"][f"rod_{law}"] = 100 * rms / excursion
            prog["d3_mean_error_rad"][f"rod_{law}"] = float(
                _angle(poses[..., 3:], el_poses[..., 3:]).mean()
            )
            prog["workspace_xy_m"][f"rod_{law}"] = np.ptp(poses[..., :2].reshape(-1, 2), 0).tolist()
        results[domain] = {"step": step, "programs": prog}
    bar.close()
    worst = max(
        max(statics["error_pct_length"]["rod_gazzola"]),
        results["source"]["step"]["max_error_pct_length"]["rod_gazzola"],
        results["constrained"]["step"]["max_error_pct_length"]["rod_gazzola"],
    )
    results["target"] = {
        "limit_pct_length": LIMIT_PCT_LENGTH,
        "worst_static_or_step_pct_length": worst,
        "met": worst <= LIMIT_PCT_LENGTH,
    }
    results["machine"] = cpu_model()
    results["versions"] = _versions()
    results["wall_s"] = time.perf_counter() - t_start
    return results


def _versions() -> dict:
    from importlib.metadata import version

    return {name: version(name) for name in ("pyelastica", "jax", "numpy")}


def to_markdown(r: dict) -> str:
    """The report as markdown."""
    names = ["pyelastica"] + [f"rod_{law}" for law in r["laws"]]
    label = {
        "pyelastica": "PyElastica 1.0",
        "rod_gazzola": "our rod (Gazzola, default)",
        "rod_linear": "our rod (linear, earlier)",
    }
    lines = [
        "# The reference rod against PyElastica",
        "",
        f"`python -m mjx_arm.xcheck --out results` on {r['machine']} ({r['wall_s']:.0f} s;"
        f" {', '.join(f'{k} {v}' for k, v in r['versions'].items())}). Same section, mass,"
        f" material, {r['n_elements']} elements, the paper code's damper at 2e-4 s, valves,"
        " gravity; chamber loads as rest strains; PyElastica clamped like the reference rod"
        " (`mjx_arm.xcheck`). Errors in % of the rod's length L = 0.2 m.",
        "",
        f"**Target (static and step-response tip within {r['target']['limit_pct_length']:g}% of L):"
        f" {'met' if r['target']['met'] else 'MISSED'}**, worst"
        f" {r['target']['worst_static_or_step_pct_length']:.3g}% of L for the default law.",
        "",
        "## Statics: chamber 0 alone, lateral tip displacement from rest (mm)",
        "",
        "| model | "
        + " | ".join(f"{p:g} bar" for p in r["statics"]["pressures_bar"])
        + " | tip error vs PyElastica (% L) |",
        "|---|" + "---|" * (len(r["statics"]["pressures_bar"]) + 1),
    ]
    for n in names:
        err = r["statics"]["error_pct_length"].get(n)
        err_txt = "-" if err is None else " / ".join(f"{e:.3g}" for e in err[1:4])
        lines.append(
            f"| {label[n]} | "
            + " | ".join(f"{v:.1f}" for v in r["statics"]["lateral_tip_mm"][n])
            + f" | {err_txt} |"
        )
    c = r["common_mode"]
    lines += [
        "",
        f"## Common mode: bend at {c['commands_bar'][0]} bar, then 1.3 bar more on every chamber",
        "",
        "| model | bend (deg) | with common mode (deg) | drop (deg) |",
        "|---|---|---|---|",
    ]
    for n in names:
        b = c["bend_deg"][n]
        lines.append(f"| {label[n]} | {b[0]:.2f} | {b[1]:.2f} | {c['bend_drop_deg'][n]:.2f} |")
    lines += [
        "",
        "## Step response (chamber 0 to 2 bar, valve included) and held-out programs",
        "",
        "| domain | model | 63% time (s) | step: max tip error (% L) | programs: tip RMS (% L)"
        " | (% excursion) | d3 mean error (rad) | workspace x by y (cm) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for domain in ("source", "constrained"):
        s, p = r[domain]["step"], r[domain]["programs"]
        for n in names:
            ws = p["workspace_xy_m"][n]
            row = [domain, label[n], f"{s['t63_s'][n]:.3g}"]
            if n == "pyelastica":
                row += ["-", "-", "-", "-"]
            else:
                row += [
                    f"{s['max_error_pct_length'][n]:.3g}",
                    f"{p['tip_rms_pct_length'][n]:.3g}",
                    f"{p['tip_rms_pct_excursion'][n]:.3g}",
                    f"{p['d3_mean_error_rad'][n]:.3g}",
                ]
            row.append(f"{100 * ws[0]:.1f} x {100 * ws[1]:.1f}")
            lines.append("| " + " | ".join(row) + " |")
    p = r["source"]["programs"]
    lines += [
        "",
        f"Programs: seeds {p['seeds']}, {p['seconds']:g} s each, random targets held 0.5-3 s"
        " (`mjx_arm.programs.held_program`), never used by the fit or the fidelity report.",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m mjx_arm.xcheck",
        description=__doc__.splitlines()[0].rstrip(".")
        + ". Writes xcheck_pyelastica.md and .json into --out (committed: --out results).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--out", type=Path, required=True, help="folder for the report")
    parser.add_argument("--seconds", type=float, default=PROGRAM_SECONDS, help="program length (s)")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.seconds) and args.seconds >= 1.0):
        parser.error("--seconds must be a finite number >= 1")
    run_folder.check_out(parser, "--out", args.out)
    _elastica()  # refuse before any work when the extra is missing
    results = run(program_seconds=args.seconds)
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_atomically(
        args.out / "xcheck_pyelastica.json",
        lambda f: f.write(json.dumps(results, indent=2).encode()),
    )
    atomic.write_atomically(
        args.out / "xcheck_pyelastica.md", lambda f: f.write(to_markdown(results).encode())
    )
    print(f"wrote {args.out / 'xcheck_pyelastica.md'} and .json ({results['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
