"""The chain against the reference rod on the five shapes' programs, untranslated, in D_s and D_c.

The fidelity report's babbling programs measure the chain against the rod on held-out data; the
five shapes are the programs every table is scored on, so how far the chain is from the rod on
them says how far a table scored in the chain can be from one scored in the paper's kind of
simulator (`eval.shapes --simulator rod`). Each shape's D_s program (60 s, 600 commands at 10 Hz)
runs from rest in both arms in each domain, with no translation and no hold: nothing is trained,
tuned or chosen here. A section of `python -m mjx_arm.fidelity` (`--only shapes` recomputes just
this section into an existing report: about 30 s on one CPU core, against the report's 15 min).
"""

from __future__ import annotations

import time

import numpy as np

from mjx_arm import programs
from mjx_arm.arm import load
from mjx_arm.model_gen import ArmParams
from mjx_arm.rod_arm import load_rod

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


def shape_comparison(duration_s: float = 60.0, log=print) -> dict:
    """{"duration_s", "arm_length_m", "table": {domain: {shape: row}}}: per shape and domain the
    tip RMS and largest difference between the chain (MuJoCo C, the committed model) and the rod
    (float64) in cm and as a fraction of L, and the rod's RMS tip excursion from rest."""
    if not duration_s > 0:
        raise ValueError(f"duration_s must be > 0, got {duration_s}")
    length_m = ArmParams().length_m
    shapes = {name: make(duration_s) for name, make in programs.SHAPES.items()}
    batch = np.stack(list(shapes.values()))
    rest_program = np.full((1, batch.shape[1], 3), programs.P_LOW_BAR)
    table = {}
    for domain in DOMAINS:
        t0 = time.perf_counter()
        chain_poses = load(domain=domain).rollout(batch, backend="c")
        rod = load_rod(domain)
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
        log(f"shapes, {domain}: {len(shapes)} programs in {time.perf_counter() - t0:.1f} s")
    return {"duration_s": duration_s, "arm_length_m": length_m, "table": table}


def shapes_lines(result: dict) -> list[str]:
    """The report's section: one table, a row per shape and domain."""
    lines = [
        "",
        "## The five shapes' programs (chain against rod)",
        "",
        f"Each shape's D_s program ({result['duration_s']:.0f} s), untranslated, from rest in"
        " both arms; the chain in MuJoCo C, the rod (`mjx_arm.load_rod`) in float64. The tables"
        " scored in the chain can differ from the same tables scored in the rod by about this.",
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
