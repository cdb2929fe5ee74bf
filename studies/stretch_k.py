"""The stretch factor k each target arm gets on the validation program, as `eval.shapes` picks it.

`tracking.held.choose_stretch_k` on `mjx_arm.programs.validation_program()` (never a test shape)
for each target domain: the k whose stretched program tracks the source arm's poses best. The
paper chain distils its translators at these k (`experiments/paper.json`).

    python -m studies.stretch_k --out studies/results/cpu/stretch_k
"""

from __future__ import annotations

import mjx_arm
from bench import run_header, write_results
from ccgan.cli import cli_parser
from mjx_arm.programs import validation_program
from studies.checks import parse_checked_args
from tracking.held import choose_stretch_k

#: The candidates `eval.shapes` tries (its EvalConfig.hold_factors).
CANDIDATES = (1, 5, 10, 15, 20, 25, 30)


def main(argv=None) -> None:
    p = cli_parser("studies.stretch_k", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--domains", nargs="+", default=["constrained", "aged"])
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    arm_s = mjx_arm.load(a.model, "source")
    program = validation_program()
    rows = {}
    for domain in a.domains:
        k, errors = choose_stretch_k(arm_s, mjx_arm.load(a.model, domain), program, CANDIDATES)
        rows[domain] = {"k": k, "x_err_cm": {str(c): e for c, e in errors.items()}}
        print(f"{domain}: k = {k}")
    header = run_header("studies.stretch_k", argv)
    lines = ["", "Mean X_err (cm) of the stretched validation program, per k.", ""]
    lines += ["| domain | k | " + " | ".join(f"k={c}" for c in CANDIDATES) + " |"]
    lines += ["|---|---|" + "---|" * len(CANDIDATES)]
    for domain, row in rows.items():
        errs = " | ".join(f"{row['x_err_cm'][str(c)]:.3f}" for c in CANDIDATES)
        lines.append(f"| {domain} | {row['k']} | {errs} |")
    title = f"Stretch factor k on the validation program, {a.model}"
    write_results(a.out, header, {"model": a.model, "rows": rows}, title, lines)


if __name__ == "__main__":
    main()
