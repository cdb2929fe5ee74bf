"""Does the rod's difference from the identified arm along one translator's commands predict it
along another's? The premise of `ccgan.distill --correction-translator` (issue 50 (d)).

One step of iterative learning control corrects the teacher's targets by d(u0) = rod(u0) -
arm(u0), the tip difference between the reference rod and the arm identified from its babbling
along the correction translator's commands u0, and the new translator's commands u1 then meet
d(u1) in the rod. The step helps as far as d(u1) is d(u0): here both are measured, u0 and u1 the
commands of two translators that hold the same k, and of stretch only (the D_s program held
k periods: commands far from u0's), on held-out programs of each family
(`studies.rod_transfer.programs_by_family`, never a test shape). Each translator reads the
chain's D_s path (what the correction's teacher tracks). Reported per family (cm, RMS over
programs and kept poses): |d(u0)|, |d(u)| and |d(u) - d(u0)| (the error left in the rod if the
arm traced the corrected target exactly), beside |arm(u) - arm(u0)|, how far apart the two
commands' paths are.

    python -m studies.correction_transfer --teach-domain \\
        results/paper/chain_2026-11-28/run/identify_rod/identify.json \\
        --u0 studies/results/h200/rod_source/chain_source/translator_seed0.ckpt \\
        --u1 studies/results/h200/rod_source/rod_source/translator_seed0.ckpt \\
        --out studies/results/cpu/correction_transfer/correction_transfer
"""

from __future__ import annotations

import time

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan import load_translator
from ccgan.cli import cli_parser
from mjx_arm import domains
from studies.checks import parse_checked_args
from studies.rod_transfer import programs_by_family


def rms_cm(difference: np.ndarray) -> float:
    """RMS tip distance (cm) of pose differences [..., 6] (m): over every leading index."""
    return float(100 * np.sqrt(np.mean(np.sum(difference[..., :3] ** 2, -1))))


def main(argv=None) -> None:
    p = cli_parser("studies.correction_transfer", __doc__)
    p.add_argument("--teach-domain", required=True, help="the identified arm's Domain file")
    p.add_argument("--u0", required=True, help="the correction translator (a .ckpt)")
    p.add_argument("--u1", required=True, help="another translator of the same k")
    p.add_argument("--model", default="models/softarm.xml")
    p.add_argument("--target-domain", default="constrained", help="the rod's domain")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    p.add_argument("--n-shape-like", type=int, default=2, help="per held-out split (2 splits)")
    p.add_argument("--n-other", type=int, default=1, help="per unseen family")
    p.add_argument("--duration-s", type=float, default=60.0)
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    if a.n_shape_like < 1 or a.n_other < 0 or a.duration_s <= 0:
        p.error("--n-shape-like must be >= 1, --n-other >= 0 and --duration-s > 0")
    u0_tr, u1_tr = load_translator(a.u0), load_translator(a.u1)
    if u0_tr.k != u1_tr.k:
        p.error(f"--u0 holds k = {u0_tr.k}, --u1 k = {u1_tr.k}: they must hold the same k")
    t0 = time.perf_counter()
    identified = domains.read_domain_file(a.teach_domain).domain
    arm_s = mjx_arm.load(a.model, "source")
    arm_c = mjx_arm.load(a.model, identified)
    rod_c = mjx_arm.load_rod(a.target_domain, dtype=a.dtype)
    programs, families = programs_by_family(a.n_shape_like, a.n_other, a.duration_s)
    x_s = arm_s.rollout(programs, backend="c")
    k = u0_tr.k
    commands_of = {
        name: np.stack([tr.translate(q, x)[0] for q, x in zip(programs, x_s, strict=True)])
        for name, tr in (("u0", u0_tr), ("u1", u1_tr))
    }
    commands_of["stretch"] = np.repeat(programs, k, axis=1)  # the D_s program held k periods
    d, in_arm = {}, {}
    for name, commands in commands_of.items():
        in_arm[name] = arm_c.rollout(commands, backend="c")[:, k - 1 :: k]
        d[name] = rod_c.rollout(commands)[:, k - 1 :: k] - in_arm[name]
        print(
            f"{name}: {len(programs)} programs in the rod and the arm"
            f" ({time.perf_counter() - t0:.0f} s)"
        )
    groups = {"all": np.arange(len(programs))}
    for family in dict.fromkeys(families):
        groups[family] = np.flatnonzero(np.asarray(families) == family)
    rows = {}
    for group, idx in groups.items():
        rows[group] = {"n": int(len(idx))}
        for other in ("u1", "stretch"):
            rows[group] |= {
                f"d_{other}_cm": rms_cm(d[other][idx]),
                f"d_{other}_minus_d_u0_cm": rms_cm(d[other][idx] - d["u0"][idx]),
                f"arm_{other}_minus_arm_u0_cm": rms_cm(in_arm[other][idx] - in_arm["u0"][idx]),
            }
        rows[group]["d_u0_cm"] = rms_cm(d["u0"][idx])
    lines = [
        "",
        f"Tip differences rod - arm (cm, RMS over programs and every k-th pose, k = {k}), the"
        f" rod in {a.target_domain} ({a.dtype}), the arm identified ({a.teach_domain}):"
        f" {a.duration_s:g} s programs; u0 {a.u0}, u1 {a.u1}.",
        "",
        "u: the commands; arm(u), rod(u): the tip path each traces; d(u) = rod(u) - arm(u).",
        "",
        "| family | programs | d(u0) | d(u1) | d(u1) - d(u0) | arm(u1) - arm(u0) |"
        " d(stretch) | d(stretch) - d(u0) | arm(stretch) - arm(u0) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for group, row in rows.items():
        lines.append(
            f"| {group} | {row['n']} | {row['d_u0_cm']:.3f} | {row['d_u1_cm']:.3f} |"
            f" {row['d_u1_minus_d_u0_cm']:.3f} | {row['arm_u1_minus_arm_u0_cm']:.3f} |"
            f" {row['d_stretch_cm']:.3f} | {row['d_stretch_minus_d_u0_cm']:.3f} |"
            f" {row['arm_stretch_minus_arm_u0_cm']:.3f} |"
        )
    result = {"k": k, "families": families, "rows": rows, "wall_s": time.perf_counter() - t0}
    print("\n".join(lines))
    write_results(
        a.out,
        run_header("studies.correction_transfer", argv),
        result,
        "The rod's difference from the identified arm along two translators' commands",
        lines,
    )


if __name__ == "__main__":
    main()
