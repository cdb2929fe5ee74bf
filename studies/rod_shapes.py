"""The chain against the reference rod on the five shapes' programs, untranslated, in D_s and D_c.

`results/fidelity.md` measures the chain against the rod on held-out babbling; the five shapes
are the programs every table is scored on, so how far the chain is from the rod on them says how
far a table scored in the chain can be from one scored in the paper's kind of simulator. Each
shape's D_s program (60 s, 600 commands at 10 Hz) runs from rest in both arms in each domain,
with no translation and no hold: nothing is trained, tuned or chosen here.

    python -m studies.rod_shapes --out studies/results/cpu/rod_shapes

Writes rod_shapes.md and rod_shapes.json. Per shape and domain: the tip RMS and largest
difference between the chain (MuJoCo C) and the rod (`mjx_arm.load_rod`, float64), in cm and as
a fraction of the arm's length, and the rod's RMS tip excursion from its rest for scale.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import mjx_arm  # (before jax: sets the XLA CPU flag)
from bench import run_header, write_results
from mjx_arm import programs
from mjx_arm.model_gen import ArmParams
from studies.checks import parse_checked_args

#: The domains both arms model the same way (`mjx_arm.rod_arm` maps them).
DOMAINS = ("source", "constrained")
CM = 100.0


def tip_differences(chain_poses: np.ndarray, rod_poses: np.ndarray) -> tuple[float, float]:
    """(RMS, largest) tip distance in m between two pose sequences [T, 6] (xyz in m first)."""
    distance = np.linalg.norm(chain_poses[:, :3] - rod_poses[:, :3], axis=-1)
    return float(np.sqrt(np.mean(distance**2))), float(distance.max())


def rms_excursion(poses: np.ndarray, rest_tip: np.ndarray) -> float:
    """RMS distance in m of the tip [T, 6] from its rest position [3]."""
    return float(np.sqrt(np.mean(np.sum((poses[:, :3] - rest_tip) ** 2, axis=-1))))


def run(duration_s: float = 60.0, log=print) -> dict:
    """{domain: {shape: row}} of the chain against the rod on the shapes' programs."""
    length_m = ArmParams().length_m
    shapes = {name: make(duration_s) for name, make in programs.SHAPES.items()}
    batch = np.stack(list(shapes.values()))
    rest_program = np.full((1, batch.shape[1], 3), programs.P_LOW_BAR)
    table = {}
    for domain in DOMAINS:
        t0 = time.perf_counter()
        chain = mjx_arm.load(domain=domain)
        rod = mjx_arm.load_rod(domain)
        chain_poses = chain.rollout(batch, backend="c")
        rod_poses = rod.rollout(batch)
        rod_rest = rod.rollout(rest_program)[0, -1, :3]
        table[domain] = {}
        for i, name in enumerate(shapes):
            rms, largest = tip_differences(chain_poses[i], rod_poses[i])
            excursion = rms_excursion(rod_poses[i], rod_rest)
            table[domain][name] = {
                "tip_rms_cm": rms * CM,
                "tip_max_cm": largest * CM,
                "tip_rms_of_length": rms / length_m,
                "rod_rms_excursion_cm": excursion * CM,
                "tip_rms_of_excursion": rms / excursion,
            }
        log(f"{domain}: {len(shapes)} shapes in {time.perf_counter() - t0:.1f} s")
    return {"duration_s": duration_s, "arm_length_m": length_m, "table": table}


def report_lines(result: dict) -> list[str]:
    """The markdown body: one table, a row per shape and domain."""
    lines = [
        "",
        f"Each shape's D_s program ({result['duration_s']:.0f} s), untranslated, from rest in"
        " both arms; the chain in MuJoCo C, the rod (`mjx_arm.load_rod`) in float64.",
        "",
        "| domain | shape | tip RMS cm | % of L | largest cm | rod's RMS excursion cm"
        " | RMS / excursion |",
        "|---|---|---|---|---|---|---|",
    ]
    for domain, rows in result["table"].items():
        for shape, row in rows.items():
            lines.append(
                f"| {domain} | {shape.replace('_', ' ')} | {row['tip_rms_cm']:.2f}"
                f" | {100 * row['tip_rms_of_length']:.1f}% | {row['tip_max_cm']:.2f}"
                f" | {row['rod_rms_excursion_cm']:.2f} | {100 * row['tip_rms_of_excursion']:.0f}% |"
            )
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m studies.rod_shapes", description=__doc__)
    parser.add_argument("--out", required=True, help="folder for rod_shapes.md and .json")
    parser.add_argument("--seconds", type=float, default=60.0, help="program length (s)")
    args = parse_checked_args(parser, argv)
    if not args.seconds > 0:
        parser.error(f"--seconds must be > 0, got {args.seconds}")
    result = run(args.seconds)
    path = write_results(
        f"{args.out}/rod_shapes",
        run_header("studies.rod_shapes", argv),
        result,
        "The chain against the reference rod on the five shapes",
        report_lines(result),
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
