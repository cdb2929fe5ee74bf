"""From a new arm's logs to a translator, in one command: ``python -m ccgan.adapt``.

A user whose arm moved into another medium, or aged, has its babbling logs, not its parameters.
This runs the two steps that make a translator from them alone:

1. **identify** (`mjx_arm.identify`): the chain of --model is fitted to the logs (a
   `python -m mjx_arm.babble` folder or file: <domain>_train.npz fitted, <domain>_val.npz held
   out), its medium's drag and its stiffness scale, from the paper's nominal medium (viscosity
   x10 the source's). Writes DIR/identify/identify.json and identify.md.
2. **teach** (`ccgan.distill --teach-domain`): the receding-horizon teacher plans in the
   identified arm, k is chosen there (stretch only's best on eval's validation program among
   --k-candidates), and the start translators (default: the committed chain's CCGAN-GP, three
   seeds) are distilled there. Writes DIR/translator/translator.ckpt (and one per seed),
   labelled for target domain "identified" and recording the identify.json it was taught on.

The logs' own arm is used for nothing else: no parameter of it is read. The settings are the
chain's data-only stage's (`experiments/paper.json`, ident_sim: 240 programs of 60 s, sized for
one GPU); ``--quick`` makes a tiny translator in a few minutes on a CPU, to try the path. More
`ccgan.distill` options follow a ``--``.

    python -m ccgan.adapt --data LOGS --out DIR [--t63 S] [--quick] [-- --epochs 200 ...]

With ``--t63`` (the arm's 63% step time from one step test on it), k is set by the rule
`K_PER_T63_S` x t63 instead of chosen in the identified arm.

    import ccgan
    translator = ccgan.load_translator("DIR/translator/translator.ckpt", method="distill",
                                       target_domain="identified")
    commands_c, k = translator.translate(pressures_s, poses_s)
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from ccgan.cli import check_output_dir, cli_parser
from ccgan.media_range import K_PER_T63_S, k_from_step_time  # the k rule's home
from mjx_arm import constants
from mjx_arm.domains import IDENTIFIED

#: The start translators: the committed chain's CCGAN-GP (D_s -> D_c), one file per seed.
START_RUN = constants.ROOT / "results" / "paper" / "rerun_2026-11-27" / "run" / "ccgan"
START_SEEDS = (0, 1, 2)
#: The paper's nominal medium, where identification starts: ten times the source's viscosity.
NOMINAL_VISCOSITY_SCALE = 10.0
#: Hold factors the teacher's k is chosen among: D_c's (15) and the aged arm's (25) inside.
K_CANDIDATES = (10, 15, 20, 25, 30)
#: `ccgan.distill` settings of the chain's ident_sim stage (teacher and distillation in one run).
CHAIN_SETTINGS = (
    "--duration-s 60 --n-train 120 --n-train-full 120 --n-val 8 --n-val-full 8"
    " --teacher-shard 256 --window-s 60 --batch-size 80 --horizon-steps 1 --iterations 1"
    " --teacher-backend mjx --teacher-substeps 2 --learning-rate 1e-3 --final-lr-factor 0.02"
    " --epochs 1840 --eval-every 1840 --generator-unroll 10 --score-substeps 5"
).split()
#: A tiny run to try the path on a CPU (not a useful translator).
QUICK_SETTINGS = (
    "--duration-s 2 --n-train 2 --n-val 1 --epochs 2 --batch-size 2 --eval-every 1"
    " --teacher-backend mjx --teacher-substeps 5 --horizon-steps 1 --iterations 1"
    " --teacher-shard 2 --window-s 2 --generator-unroll 2 --score-substeps 5"
    " --k-choice-seconds 4"
).split()


def build_parser() -> argparse.ArgumentParser:
    p = cli_parser("ccgan.adapt", __doc__)
    p.add_argument(
        "--data", required=True, help="the arm's babbling: a mjx_arm.babble folder or file"
    )
    p.add_argument("--out", required=True, help="folder for identify/ and translator/")
    p.add_argument(
        "--data-domain",
        help="which <domain>_train.npz of a --data folder (default: the only one besides source)",
    )
    p.add_argument("--model", default=str(constants.TRANSLATOR_MODEL_PATH), help="the chain's MJCF")
    p.add_argument(
        "--translators",
        nargs="+",
        default=[str(START_RUN / f"translator_seed{s}.ckpt") for s in START_SEEDS],
        help="start translators (D_s -> D_c, labelled constrained)",
    )
    p.add_argument("--n-programs", type=int, help="identify on the first N training programs")
    p.add_argument("--k-candidates", type=int, nargs="+", default=list(K_CANDIDATES))
    p.add_argument(
        "--t63",
        type=float,
        help="the arm's 63%% step time (s), from one step test on it (chamber 0 to 2 bar): k is"
        f" then {K_PER_T63_S} x t63, the nearest of --k-candidates, instead of chosen in the"
        " identified arm (which misses a real arm's k when the chain's family cannot hold it:"
        " docs/media_range.md)",
    )
    p.add_argument("--quick", action="store_true", help="tiny settings, to try the path on a CPU")
    return p


def data_domain(data: Path, asked: str | None) -> str:
    """The domain whose <domain>_train.npz the logs hold: `asked`, else the only one that is not
    the source's.

    Raises:
      ValueError: none, or several without `asked`.
    """
    if asked or data.is_file():
        return asked or ""
    names = sorted(p.name.removesuffix("_train.npz") for p in data.glob("*_train.npz"))
    names = [n for n in names if n != "source"]
    if len(names) != 1:
        raise ValueError(
            f"{data} holds {names or 'no <domain>_train.npz'}: give --data-domain"
            if names
            else f"{data} holds no <domain>_train.npz besides source_train.npz"
        )
    return names[0]


def main(argv: list[str] | None = None) -> int:
    from ccgan import distill
    from mjx_arm import identify

    argv = list(sys.argv[1:] if argv is None else argv)
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []
    own = argv[: argv.index("--")] if "--" in argv else argv
    p = build_parser()
    a = p.parse_args(own)
    data, out = Path(a.data), Path(a.out)
    if not data.exists():
        p.error(f"--data {data}: no such file or folder")
    try:
        domain = data_domain(data, a.data_domain)
    except ValueError as err:
        p.error(str(err))
    for path in a.translators:
        if not Path(path).is_file():
            p.error(f"--translators: {path} is not a file")
    if a.t63 is not None and not (a.t63 > 0 and math.isfinite(a.t63)):
        p.error(f"--t63 must be a positive number of seconds, got {a.t63}")
    check_output_dir(p, "--out", str(out))
    started = time.perf_counter()
    identify_argv = ["--data", str(data), "--out", str(out / "identify"), "--model", a.model]
    identify_argv += ["--base-viscosity-scale", f"{NOMINAL_VISCOSITY_SCALE:g}", "--no-progress"]
    identify_argv += ["--domain", domain] if domain else []
    identify_argv += ["--n-programs", str(a.n_programs)] if a.n_programs else []
    print(f"identify: python -m mjx_arm.identify {' '.join(identify_argv)}", flush=True)
    rc = identify.main(identify_argv)
    if rc:
        return rc
    identified_s = time.perf_counter() - started
    seeds = [str(s) for s in range(len(a.translators))]
    distill_argv = ["--translators", *a.translators, "--seeds", *seeds, "--model", a.model]
    distill_argv += ["--domain", IDENTIFIED, "--start-domain", "constrained"]
    distill_argv += ["--teach-domain", str(out / "identify" / "identify.json")]
    if a.t63 is None:
        distill_argv += ["--k-candidates", *map(str, a.k_candidates)]
    else:
        distill_argv += ["--hold-factor", str(k_from_step_time(a.t63, a.k_candidates))]
    distill_argv += ["--out", str(out / "translator")]
    distill_argv += (QUICK_SETTINGS if a.quick else CHAIN_SETTINGS) + extra
    print(f"teach: python -m ccgan.distill {' '.join(distill_argv)}", flush=True)
    distill.main(distill_argv)
    summary = {
        "identify_s": identified_s,
        "total_s": time.perf_counter() - started,
        "identify": str(out / "identify" / "identify.json"),
        "translator": str(out / "translator" / "translator.ckpt"),
        "commands": {"identify": identify_argv, "distill": distill_argv},
    }
    (out / "adapt.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(
        f"translator: {summary['translator']} ({summary['total_s']:.0f} s); use it with"
        f' ccgan.load_translator("{summary["translator"]}", method="distill",'
        f' target_domain="{IDENTIFIED}")'
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
