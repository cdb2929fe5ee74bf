"""Fits the MuJoCo arm to the reference Cosserat rod on babbling data.

Four numbers are fitted, in log space, by `mujoco.minimize.least_squares` (Levenberg-Marquardt
with finite differences, each residual a MuJoCo C rollout of the generated model):

  * `stiffness_scale`: multiplies every joint stiffness (bend, twist, stretch) derived from E, G;
  * `chamber_gain_scale`: multiplies the chamber force per bar (pressure x lumen area);
  * `medium_drag_ns_per_m2`: the source medium's drag per unit length (sets the viscosity);
  * `constrained_viscosity_scale`: the constrained medium's viscosity over the source's.

The data are tip poses of the rod (`mjx_arm.cosserat` with the arm's section and mass, the paper
code's per-mass damping 800 / 8000 1/s and its 2e-4 s step) under seeded babbling programs that
`python -m mjx_arm.fidelity` never uses (seeds `FIT_SEEDS`; fidelity tests on seeds 0-2), with
holds of up to 30 s so the constrained medium's slow settling weighs in. Residuals are tip
position errors (m) and d3 errors times the arm length, both domains together, over every 10 Hz
sample.

Stiffness, gain and drag can trade off almost freely in an overdamped arm (scaling all three
changes nothing but the weight of inertia), and the chain's statics already follow from the
section with no fitting (chamber couples and springs are exact per joint), so a strong prior
holds stiffness and gain at their physical values and the data fit the two media. With a weak
prior the fit moves stiffness and gain apart, which trades the statics and the constrained
medium's slow settling for a little babbling error.

The joints carry no damping: the rod has no material damping, only the medium's.

Run `python -m mjx_arm.fit --out FIT.json` to fit and write the result; add `--write-model` to
make it the committed fit: `models/softarm_fit.json` and `models/softarm.xml` regenerated from
it, the two written together.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import math
import sys
import time
from pathlib import Path

import mujoco.minimize
import numpy as np
from tqdm import tqdm

import mjx_arm
from mjx_arm import constants, cosserat, domains, fitted, run_folder
from mjx_arm.arm import SimulationDivergedError
from mjx_arm.machine import cpu_model
from mjx_arm.model_gen import ArmParams, generate_xml
from mjx_arm.programs import held_program

#: Babbling seeds of the fit data (the fidelity report holds out seeds 0-2).
FIT_SEEDS = (100, 101, 102)
#: Seconds of babbling per seed and domain.
FIT_SECONDS = 120.0
#: Each random target is held 0.5-30 s (control periods), longer than the fidelity protocol's
#: 0.5-3 s, so the slow settling of the constrained medium weighs in the fit.
FIT_HOLD_PERIODS = (5, 300)
FIT_DOMAINS = ("source", "constrained")
#: Fitted names in the order of the parameter vector (log values).
NAMES = fitted.FIT_NAMES
#: Weight (m per unit of log) of the prior pulling stiffness and gain toward 1.
PRIOR_WEIGHT_M = 0.3
#: Log-space box: each factor stays within 1/8 .. 8 times its starting value.
LOG_BOUND = math.log(8.0)
#: Finite-difference step in log space (the MJCF keeps 6 significant digits, so ~1e-6 is noise).
FD_STEP = 1e-3
#: Residual of a rollout that diverged (m), large against any real error.
DIVERGED_M = 1.0


def params_from_log(x: np.ndarray, base: ArmParams = ArmParams()) -> ArmParams:
    """The arm parameters at log-parameter vector `x` (order `NAMES`)."""
    return dataclasses.replace(
        base, **dict(zip(NAMES, np.exp(np.asarray(x, float)).tolist(), strict=True))
    )


def unfitted_values(base: ArmParams = ArmParams()) -> dict[str, float]:
    """The physical values, nothing fitted: the fit's start and its prior's centre."""
    return fitted.unfitted(base.mass_kg / base.length_m)


def domain_of(params: ArmParams, name: str) -> domains.Domain:
    """The fit domain `name` for `params` (the constrained one at its viscosity scale)."""
    if name == "source":
        return domains.Domain(name="source")
    return domains.Domain(name=name, viscosity_scale=params.constrained_viscosity_scale)


def initial_log() -> np.ndarray:
    """Starting point: the physical values, nothing fitted (`unfitted_values`)."""
    start = unfitted_values()
    return np.log([start[name] for name in NAMES])


def reference_data(seeds=FIT_SEEDS, seconds: float = FIT_SECONDS) -> dict[str, dict]:
    """Programs [N, T, 3] (bar) and rod poses [N, T, 6] for each fit domain."""
    programs = np.stack([held_program(s, seconds, FIT_HOLD_PERIODS) for s in seeds])
    out = {}
    for domain in FIT_DOMAINS:
        params = cosserat.CosseratParams.from_arm(ArmParams(), domain)
        out[domain] = {"programs": programs, "poses": cosserat.rollout(programs, params)}
    return out


def pose_residuals(poses: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Flat residuals (m): tip position errors and d3 errors times the arm length, scaled by
    1 / sqrt(samples) so the squared norm is a mean."""
    length = ArmParams().length_m
    diff = np.concatenate(
        [poses[..., :3] - target[..., :3], length * (poses[..., 3:] - target[..., 3:])], -1
    )
    return diff.ravel() / math.sqrt(diff.shape[0] * diff.shape[1])


def simulate(params: ArmParams, data: dict[str, dict]) -> dict[str, np.ndarray]:
    """MuJoCo C poses [N, T, 6] of the arm `params` in each fit domain."""
    xml = generate_xml(params)
    out = {}
    for domain, item in data.items():
        arm = mjx_arm.load(xml=xml, domain=domain_of(params, domain))
        out[domain] = arm.rollout(item["programs"], backend="c")
    return out


def residual_one(x: np.ndarray, data: dict[str, dict], base: ArmParams = ArmParams()) -> np.ndarray:
    """Residual vector of one log-parameter vector."""
    try:
        poses = simulate(params_from_log(x, base), data)
        fits = [pose_residuals(poses[d], data[d]["poses"]) for d in FIT_DOMAINS]
    except SimulationDivergedError:
        fits = [np.full(data[d]["poses"].size, DIVERGED_M) for d in FIT_DOMAINS]
    prior = PRIOR_WEIGHT_M * (np.asarray(x[:2]) - initial_log()[:2])
    return np.concatenate(fits + [prior])


def rms_errors(poses: dict[str, np.ndarray], data: dict[str, dict]) -> dict[str, dict[str, float]]:
    """Tip RMS error (m) and mean d3 angle error (rad) per domain."""
    out = {}
    for domain, item in data.items():
        err = np.linalg.norm(poses[domain][..., :3] - item["poses"][..., :3], axis=-1)
        cos = np.clip(np.sum(poses[domain][..., 3:] * item["poses"][..., 3:], -1), -1.0, 1.0)
        out[domain] = {
            "tip_rms_m": float(np.sqrt(np.mean(err**2))),
            "d3_mean_rad": float(np.arccos(cos).mean()),
        }
    return out


def fit(
    data: dict[str, dict],
    max_iter: int = 30,
    log=print,
    progress: bool = False,
    base: ArmParams = ArmParams(),
) -> dict:
    """Runs the least-squares fit from the physical values; returns the JSON-ready result.

    Args:
      data: `reference_data()`'s programs and target poses per fit domain.
      max_iter: Levenberg-Marquardt iterations at most.
      log: receives the optimiser's iteration report.
      progress: show a progress bar over the residual evaluations.
      base: the arm whose four factors are fitted (e.g. without stretch softening).
    """
    x0 = initial_log()
    evaluations = 0
    bar = tqdm(desc="fit: rollouts of both domains", unit="evaluation", disable=not progress)

    def residual(x: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        columns = x.reshape(len(NAMES), -1)
        evaluations += columns.shape[1]
        bar.update(columns.shape[1])
        out = np.stack(
            [residual_one(columns[:, j], data, base) for j in range(columns.shape[1])], axis=1
        )
        return out if x.ndim == 2 else out[:, 0]

    bounds = (x0 - LOG_BOUND, x0 + LOG_BOUND)
    report = io.StringIO()
    t0 = time.perf_counter()
    x, trace = mujoco.minimize.least_squares(
        x0,
        residual,
        bounds=bounds,
        eps=FD_STEP,
        max_iter=max_iter,
        output=report,
        xtol=1e-4,
        gtol=1e-10,
    )
    wall = time.perf_counter() - t0
    bar.close()
    log(report.getvalue().rstrip())
    before = rms_errors(simulate(params_from_log(x0, base), data), data)
    after = rms_errors(simulate(params_from_log(x, base), data), data)
    return {
        "command": "python -m mjx_arm.fit"
        + ("" if base.stretch_softening else " --constant-springs"),
        "stretch_softening": base.stretch_softening,
        "cpu": cpu_model(),
        "wall_s": wall,
        "evaluations": evaluations,
        "iterations": len(trace),
        "fitted": dict(zip(NAMES, np.exp(x).tolist(), strict=True)),
        "initial": unfitted_values(),
        "final_cost": float(trace[-1].objective) if trace else float("nan"),
        "fit_data": {
            "seeds": list(FIT_SEEDS),
            "seconds": FIT_SECONDS,
            "hold_periods": list(FIT_HOLD_PERIODS),
            "reference": "mjx_arm.cosserat: 20 elements, the arm's section and mass, damping"
            " 800 / 8000 1/s at 2e-4 s, Gazzola's law (the stretch factors)",
            "section": ArmParams().section,
        },
        "fit_error_before": before,
        "fit_error_after": after,
        "prior_weight_m": PRIOR_WEIGHT_M,
    }


def write_committed_fit(result: dict) -> None:
    """Makes `result` the committed fit: `models/softarm_fit.json` and the regenerated
    `models/softarm.xml`, both first written beside their targets, then renamed into place, so
    a failure leaves the old pair intact."""
    fit_path = fitted.FIT_PATHS[ArmParams().section]
    params = dataclasses.replace(ArmParams(), **result["fitted"])
    staged = [
        (fit_path, json.dumps(result, indent=2) + "\n"),
        (constants.DEFAULT_MODEL_PATH, generate_xml(params)),
    ]
    for path, text in staged:
        path.with_name(path.name + ".tmp").write_text(text)
    for path, _ in staged:
        path.with_name(path.name + ".tmp").replace(path)
        print(f"wrote {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m mjx_arm.fit",
        description=__doc__.splitlines()[0].rstrip(".")
        + ". Writes only --out, unless --write-model makes the fit the committed one.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "--max-iter", type=int, default=30, help="Levenberg-Marquardt iterations at most"
    )
    parser.add_argument("--out", type=Path, help="write the fit result (JSON) here")
    parser.add_argument(
        "--write-model",
        action="store_true",
        help="rewrite the committed models/softarm_fit.json and models/softarm.xml from the fit",
    )
    parser.add_argument(
        "--constant-springs",
        action="store_true",
        help="fit the chain without stretch softening (constant joint springs), for comparison;"
        " refused with --write-model",
    )
    args = parser.parse_args(argv)
    if args.constant_springs and args.write_model:
        parser.error("--constant-springs is a comparison: it cannot be the committed fit")
    if args.max_iter < 1:
        parser.error("--max-iter must be >= 1")
    if args.out is None and not args.write_model:
        parser.error("say where the fit goes: --out FILE, --write-model, or both")
    if args.out is not None:
        run_folder.check_out(parser, "--out", args.out, file=True)
    if args.write_model:
        for path in (fitted.FIT_PATHS["isupport"], constants.DEFAULT_MODEL_PATH):
            run_folder.check_out(parser, "--write-model", path, file=True)
    t0 = time.perf_counter()
    print("reference rod data ...", flush=True)
    data = reference_data()
    seconds = time.perf_counter() - t0
    print(f"reference rod data: {len(FIT_SEEDS)} x {FIT_SECONDS:g} s per domain in {seconds:.1f} s")
    base = dataclasses.replace(ArmParams(), stretch_softening=not args.constant_springs)
    result = fit(data, args.max_iter, progress=True, base=base)
    for name in NAMES:
        print(f"{name:30s} {result['initial'][name]:10.4g} -> {result['fitted'][name]:10.4g}")
    for domain in FIT_DOMAINS:
        b, a = result["fit_error_before"][domain], result["fit_error_after"][domain]
        print(
            f"{domain:12s} tip RMS {1e3 * b['tip_rms_m']:.2f} -> {1e3 * a['tip_rms_m']:.2f} mm,"
            f" d3 {1e3 * b['d3_mean_rad']:.1f} -> {1e3 * a['d3_mean_rad']:.1f} mrad"
        )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.out.with_name(args.out.name + ".tmp")
        tmp.write_text(json.dumps(result, indent=2) + "\n")
        tmp.replace(args.out)
        print(f"wrote {args.out}")
    if args.write_model:
        write_committed_fit(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
