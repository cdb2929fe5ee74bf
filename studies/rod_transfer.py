"""Translators scored in the reference rod on held-out programs, family by family (issue 50,
items 4 and 5): what a translator taught in the chain keeps when the arm is the paper's simulator.

Every program runs from rest in the rod in D_s (float64, `mjx_arm.load_rod("source")`): that
path is the target, and the translator reads it (`Translator.translate(p, x_rod)`). Its
commands, held the k the file records, run in the rod in `--target-domain`; every k-th pose is
scored (X_err, cm, mean over the program). Stretch only holds the D_s program `--stretch-k`
periods (20: the k `eval.shapes --simulator rod` picks in the rod on its validation program).

Program families (never a test shape):

- the distillation's held-out shape-like programs (`ccgan.distill.teacher.held_out_programs`:
  its "val" and "val_full" splits, the ones that pick a distillation's iterate), split by kind
  (`mjx_arm.programs.shape_like_kinds`: ellipse, polygon, staircase, phase_jumps), families the
  teacher's training programs hold;
- babbling (`mjx_arm.babble`'s holds of 0.5-3 s, the distillation's "val" babbling stream) and
  held (`mjx_arm.programs.held_program`: all chambers together, holds of 1-4 s, seeds 7000+),
  families that no distillation of the chain trains on (its `n_train_babble` is 0).

`--simulator chain` scores in the chain of --model (MuJoCo C) instead, against the chain's own
D_s path: the same families for a target the chain holds (the aged arm, a medium off the pair).

Beside each translator's error against the rod's D_s path, its error against the chain's D_s
path of the same program (`--diagnose`): a translator taught to trace the chain's D_s path
(`ccgan.distill`'s default `--source-simulator chain`) inherits the chain's D_s model error,
which the table's "D_s gap" column gives (chain against rod in D_s, no translator).

    python -m studies.rod_transfer --out studies/results/h200/rod_transfer/rod_transfer \\
        --translators chain=results/paper/rerun_2026-11-27/run/ccgan_sim/translator_seed{0,1,2}.ckpt
"""

from __future__ import annotations

import time
from collections import defaultdict

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan import load_translator
from ccgan.cli import cli_parser
from ccgan.distill.config import DistillConfig
from ccgan.distill.teacher import held_out_programs
from mjx_arm.babble import BabbleConfig
from mjx_arm.programs import babble_programs, held_program, shape_like_kinds
from studies.checks import parse_checked_args
from tracking.metrics import position_error_cm

#: Families that no chain distillation trains on (the rest are the shape-like kinds).
UNSEEN_FAMILIES = ("babbling", "held")
#: Seeds of the held family's programs (`held_program`), a stream no other command draws.
HELD_SEED0 = 7000


def programs_by_family(
    n_shape_like: int, n_other: int, duration_s: float, seed: int = 0
) -> tuple[np.ndarray, list[str]]:
    """Programs [N, T, 3] (bar, float64) and each one's family.

    Args:
      n_shape_like: held-out shape-like programs per split (the distillation's n_val and
        n_val_full), so 2 x n_shape_like in all, each labelled by its kind.
      n_other: programs of each unseen family (babbling, held).
      duration_s: length of every program (s).
      seed: the distillation's seed (its programs' streams).
    """
    if n_shape_like:
        config = DistillConfig(n_val=n_shape_like, n_val_full=n_shape_like, duration_s=duration_s)
        shape_like = held_out_programs(config).astype(np.float64)
    else:  # (a DistillConfig needs a held-out program; none of this family is asked for)
        shape_like = np.zeros((0, int(round(duration_s * mjx_arm.CONTROL_HZ)), 3))
    kinds = shape_like_kinds(n_shape_like, seed, "distill/val")
    kinds += shape_like_kinds(n_shape_like, seed, "distill/val_full")
    babble = BabbleConfig(seed=seed, duration_s=duration_s)
    babbling = babble_programs(babble, np.arange(n_other), domain="distill", split="val")
    held = [held_program(HELD_SEED0 + i, duration_s, (10, 40)) for i in range(n_other)]
    held = np.stack(held) if held else np.zeros((0, *shape_like.shape[1:]))
    programs = np.concatenate(
        [shape_like, babbling.astype(np.float64).reshape(-1, *held.shape[1:]), held]
    )
    return programs, kinds + ["babbling"] * n_other + ["held"] * n_other


def held_rollouts(rod_c, runs: list[tuple[np.ndarray, int]]) -> list[np.ndarray]:
    """Poses [T, 6] (every k-th, m) of each (commands [T, 3] per source step, k) held k periods
    in `rod_c` (a rod arm, or any arm whose `rollout(commands [B, N, 3])` returns poses
    [B, N, 6]: `chain_in_c`); runs of one k share one batched rollout."""
    by_k = defaultdict(list)
    for i, (_, k) in enumerate(runs):
        by_k[k].append(i)
    out = [None] * len(runs)
    for k, rows in by_k.items():
        held = np.stack([np.repeat(runs[i][0], k, axis=0) for i in rows])
        poses = rod_c.rollout(held)[:, k - 1 :: k]
        for row, i in enumerate(rows):
            out[i] = poses[row]
    return out


def parse_translators(p, specs: list[str]) -> dict[str, list[str]]:
    """NAME=PATH[,PATH...] -> {name: [paths]} (one path per seed); a usage error otherwise."""
    out = {}
    for spec in specs:
        name, sep, paths = spec.partition("=")
        if not sep or not name or not paths:
            p.error(f"--translators: expected NAME=PATH[,PATH...], got {spec!r}")
        out.setdefault(name, []).extend(paths.split(","))
    return out


class chain_in_c:  # noqa: N801  (stands where a rod arm stands)
    """The chain `arm` as `held_rollouts` and the D_s path call a rod arm: its `rollout` in
    MuJoCo C (multi-threaded), for `--simulator chain`."""

    def __init__(self, arm):
        self.arm = arm

    def rollout(self, commands: np.ndarray) -> np.ndarray:
        return self.arm.rollout(commands, backend="c")


def family_table(families: list[str], errors: dict[str, np.ndarray]) -> dict[str, dict]:
    """{family: {column: mean X_err (cm)}} with an "all" row, from per-program errors [N]."""
    rows = {}
    for family in [*dict.fromkeys(families), "all"]:
        mask = np.array([family in ("all", f) for f in families])
        rows[family] = {"n": int(mask.sum())} | {
            col: float(err[mask].mean()) for col, err in errors.items()
        }
    return rows


def main(argv=None) -> None:
    p = cli_parser("studies.rod_transfer", __doc__)
    p.add_argument("--translators", nargs="+", default=[], metavar="NAME=PATH[,PATH...]")
    p.add_argument("--target-domain", default="constrained")
    p.add_argument(
        "--target-domain-file",
        metavar="JSON",
        help="with --simulator chain: the chain in the Domain of this file (an identify.json or"
        ' {"domain": {...}}) instead of --target-domain, e.g. a medium off the pair (issue 50 (c))',
    )
    p.add_argument("--stretch-k", type=int, default=20)
    p.add_argument("--n-shape-like", type=int, default=8, help="per held-out split (2 splits)")
    p.add_argument("--n-other", type=int, default=4, help="per unseen family")
    p.add_argument("--duration-s", type=float, default=60.0)
    p.add_argument("--model", default="models/softarm.xml", help="the chain (for --diagnose)")
    p.add_argument("--diagnose", action="store_true", help="also score against the chain's D_s")
    p.add_argument(
        "--simulator",
        choices=("rod", "chain"),
        default="rod",
        help="the arm scored: the reference rod, or the chain of --model in MuJoCo C (e.g. the"
        " aged arm's held-out families, issue 50 (b)); its own D_s path is the target",
    )
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    if a.stretch_k < 1 or a.n_shape_like < 0 or a.n_other < 0 or a.duration_s <= 0:
        p.error("--stretch-k must be >= 1, the counts >= 0 and --duration-s > 0")
    if a.n_shape_like + a.n_other == 0:
        p.error("--n-shape-like and --n-other are both 0: no program to score")
    if a.diagnose and a.simulator == "chain":
        p.error("--diagnose compares the chain with the rod: not with --simulator chain")
    target = a.target_domain
    if a.target_domain_file:
        if a.simulator != "chain":
            p.error("--target-domain-file is for --simulator chain (the rod has its own media)")
        try:
            target = mjx_arm.domains.read_domain_file(a.target_domain_file).domain
        except (OSError, ValueError) as err:
            p.error(f"--target-domain-file: {err}")
    specs = parse_translators(p, a.translators)
    translators = {name: [load_translator(path) for path in paths] for name, paths in specs.items()}
    t0 = time.perf_counter()
    programs, families = programs_by_family(a.n_shape_like, a.n_other, a.duration_s)
    if a.simulator == "rod":
        rod_s, rod_c = mjx_arm.load_rod("source"), mjx_arm.load_rod(a.target_domain)
    else:
        rod_s, rod_c = (chain_in_c(mjx_arm.load(a.model, d)) for d in ("source", target))
    where = "the rod" if a.simulator == "rod" else f"the chain of {a.model} (MuJoCo C)"
    x_rod = rod_s.rollout(programs)
    print(f"{len(programs)} programs' D_s paths in {where} ({time.perf_counter() - t0:.0f} s)")
    errors = {}
    if a.diagnose:
        x_chain = mjx_arm.load(a.model, "source").rollout(programs, backend="c")
        errors["D_s gap (chain vs rod)"] = position_error_cm(x_chain, x_rod).mean(-1)
    runs = [(program, a.stretch_k) for program in programs]
    owners = [("stretch", None)] * len(programs)
    ks = {"stretch": a.stretch_k}
    for name, seeds in translators.items():
        seed_ks = []
        for s_i, tr in enumerate(seeds):
            for program, target in zip(programs, x_rod, strict=True):
                commands, k = tr.translate(program, target)
                runs.append((commands[k - 1 :: k], k))
                owners.append((name, s_i))
            seed_ks.append(k)
        ks[name] = seed_ks[0] if len(set(seed_ks)) == 1 else seed_ks  # each seed holds its own
    poses = held_rollouts(rod_c, runs)
    print(f"{len(runs)} rollouts in {where} ({time.perf_counter() - t0:.0f} s)")
    n = len(programs)
    errors["stretch"] = position_error_cm(np.stack(poses[:n]), x_rod).mean(-1)
    for name, seeds in translators.items():
        mine = [pose for pose, (owner, _) in zip(poses, owners, strict=True) if owner == name]
        by_seed = np.stack(mine).reshape(len(seeds), n, *mine[0].shape)
        errors[name] = position_error_cm(by_seed, x_rod[None]).mean(-1).mean(0)
        if a.diagnose:
            chain_err = position_error_cm(by_seed, x_chain[None]).mean(-1).mean(0)
            errors[f"{name} vs chain D_s"] = chain_err
    rows = family_table(families, errors)
    header = run_header("studies.rod_transfer", argv)
    cols = list(errors)
    lines = [
        "",
        f"X_err (cm, mean over each program and then the family's programs; translators: mean"
        f" of their seeds) in {where} in {a.target_domain_file or a.target_domain} against its"
        " own D_s path;"
        f" {a.duration_s:g} s programs; k: "
        + ", ".join(f"{name} {'/'.join(map(str, np.atleast_1d(k)))}" for name, k in ks.items())
        + f". Families {', '.join(UNSEEN_FAMILIES)} are in no chain distillation's training.",
        "",
        "| family | programs | "
        + " | ".join(cols)
        + " | "
        + " | ".join(f"{name} / stretch" for name in translators)
        + " |",
        "|---|---|" + "---|" * (len(cols) + len(translators)),
    ]
    for family, row in rows.items():
        ratios = [row[name] / row["stretch"] for name in translators]
        lines.append(
            f"| {family} | {row['n']} | "
            + " | ".join(f"{row[c]:.3f}" for c in cols)
            + "".join(f" | {r:.2f}x" for r in ratios)
            + " |"
        )
    result = {
        "translators": specs,
        "k": ks,
        "target_domain": a.target_domain_file or a.target_domain,
        "simulator": a.simulator,
        "families": families,
        "per_program_x_err_cm": {c: e.tolist() for c, e in errors.items()},
        "rows": rows,
        "wall_s": time.perf_counter() - t0,
    }
    title = f"Translators scored in {where} on held-out programs, by family"
    print("\n".join(lines))
    write_results(a.out, header, result, title, lines)


if __name__ == "__main__":
    main()
