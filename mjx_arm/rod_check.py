"""Checks that the rod arm (`mjx_arm.load_rod`, float64) is the committed reference rod path.

`mjx_arm.fidelity` and `mjx_arm.fit` score the chain against `cosserat.rollout` with
`CosseratParams.from_arm`; the rod arm must give the same poses, to `AGREEMENT_FRACTION_OF_L` of
the length, on the fidelity report's held-out programs (3 x 60 s, source and constrained):

    python -m mjx_arm.rod_check              # about 2 minutes on a 2-core CPU; exit status 1 if not
    python -m mjx_arm.rod_check --seconds 5  # shorter programs

A module of its own because it reads the fidelity report's programs, and `mjx_arm.fidelity`
imports the package, which exports `load_rod`.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from mjx_arm import cosserat, fidelity
from mjx_arm.model_gen import ArmParams
from mjx_arm.programs import held_program
from mjx_arm.rod_arm import AGREEMENT_FRACTION_OF_L, load_rod
from mjx_arm.rod_params import CosseratParams


def agreement(seconds: float | None = None) -> dict:
    """Largest tip and d3 differences between `RodArm` (float64) and the committed reference path
    (`cosserat.rollout` with `CosseratParams.from_arm`, as `mjx_arm.fidelity` runs it) on the
    fidelity report's held-out programs, per domain; `seconds` shortens them."""
    length = seconds or fidelity.BABBLE_SECONDS
    programs = np.stack(
        [held_program(s, length, fidelity.BABBLE_HOLD_PERIODS) for s in fidelity.BABBLE_SEEDS]
    )
    out = {}
    for domain in fidelity.DOMAINS:
        reference = cosserat.rollout(programs, CosseratParams.from_arm(ArmParams(), domain))
        rod = load_rod(domain)
        poses = rod.rollout(programs)
        tip = float(np.linalg.norm(poses[..., :3] - reference[..., :3], axis=-1).max())
        out[domain] = {
            "programs": len(programs),
            "seconds": length,
            "max_tip_fraction_of_L": tip / rod.length_m,
            "max_d3_difference": float(np.abs(poses[..., 3:] - reference[..., 3:]).max()),
        }
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m mjx_arm.rod_check",
        description="Checks that the rod arm (float64) agrees with the committed reference rod path"
        f" to {AGREEMENT_FRACTION_OF_L:g} of L on the fidelity report's programs (3 x 60 s,"
        " source and constrained; minutes on a CPU). Exit status 1 if not.",
    )
    parser.add_argument("--seconds", type=float, default=None, help="shorten the programs (s)")
    args = parser.parse_args(argv)
    result = agreement(args.seconds)
    worst = max(r["max_tip_fraction_of_L"] for r in result.values())
    for domain, r in result.items():
        print(
            f"{domain}: {r['programs']} x {r['seconds']:g} s, largest tip difference"
            f" {r['max_tip_fraction_of_L']:.3g} of L, d3 {r['max_d3_difference']:.3g}"
        )
    ok = worst <= AGREEMENT_FRACTION_OF_L
    print(("agrees" if ok else "DOES NOT agree") + f" to {AGREEMENT_FRACTION_OF_L:g} of L")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
