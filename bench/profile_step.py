"""Where a CCGAN-GP training step spends its time on the GPU: kernels per step, by part.

Times `run_epochs` like `bench.train` (forced k, no k selection), then records one call with
`jax.profiler.trace` and reads the trace back with `jax.profiler.ProfileData`. Each device
kernel is put in the part of the train step whose `jax.named_scope` it carries
(`ccgan.train`: generators_forward, critic_update, generator_losses (feedback inside it),
generators_backward); busy time is the sum of kernel durations, and the rest of the wall time
is the device waiting between kernels.

    python -m bench.profile_step --data data/babble \
        --forward-c results/solid/translators/ccgan/forward_c.ckpt \
        --feedback-impls lean lean_reduce --out bench/results/h200 --tag _dedup

Writes profile_step{tag}.md and .json to --out.
"""

from __future__ import annotations

import collections
import dataclasses
import glob
import json
import re
import tempfile
import time
from pathlib import Path

import jax

from bench import run_header
from bench.train import babbling_data, forward_c_params, synthetic_data, time_epochs
from ccgan import config as config_lib
from ccgan import train as train_lib
from ccgan.cli import cli_parser
from ccgan.models import ForwardModel

#: Named scopes of `ccgan.train`'s train step, most specific first.
PARTS = (
    "feedback",
    "generators_forward",
    "critic_update",
    "generator_losses",
    "generators_backward",
)


def _part(texts: list[str]) -> str:
    joined = " ".join(texts)
    for part in PARTS:
        if part in joined:
            return part
    return "other"


_INSTRUCTION = re.compile(r"^\s*(?:ROOT\s+)?%?([\w.\-]+) = .*")
_COMPUTATION = re.compile(r"^\s*(?:ENTRY\s+)?%?([\w.\-]+) .*\{\s*$")
_CALLS = re.compile(r"(?:calls|body|condition|to_apply)=%?([\w.\-]+)")
_OP_NAME = re.compile(r'op_name="([^"]*)"')


def op_names(hlo_text: str) -> dict[str, str]:
    """HLO instruction name -> JAX name stack (its metadata, else that of what it calls)."""
    own, calls, members = {}, {}, collections.defaultdict(list)
    computation = None
    for line in hlo_text.splitlines():
        inst = _INSTRUCTION.match(line)
        if inst:
            name = inst.group(1)
            if computation:
                members[computation].append(name)
            m = _OP_NAME.search(line)
            if m:
                own[name] = m.group(1)
            calls[name] = _CALLS.findall(line)
            continue
        comp = _COMPUTATION.match(line)
        if comp:
            computation = comp.group(1)

    def resolve(name, depth=0):
        if name in own or depth > 3:
            return own.get(name, "")
        for callee in calls.get(name, []):
            for member in members.get(callee, []):
                found = resolve(member, depth + 1)
                if found:
                    return found
        return ""

    return {name: resolve(name) for name in calls}


def device_kernels(trace_dir: str, names: dict[str, str]) -> list[dict]:
    """Kernel events [{name, dur_us, part}] of the trace's GPU planes (CPU: XLA thread lines).

    `names` maps HLO instruction names (the events' hlo_op stat) to JAX name stacks.
    """
    paths = glob.glob(f"{trace_dir}/**/*.xplane.pb", recursive=True)
    if not paths:
        raise FileNotFoundError(f"no .xplane.pb under {trace_dir}")
    data = jax.profiler.ProfileData.from_file(paths[0])
    gpu = any(plane.name.startswith("/device:GPU") for plane in data.planes)
    events = []
    for plane in data.planes:
        if gpu and not plane.name.startswith("/device:GPU"):
            continue
        if not gpu and plane.name != "/host:CPU":
            continue
        for line in plane.lines:
            # GPU: kernels appear once per CUDA stream line ("XLA Ops"/"XLA Modules" repeat
            # them at a coarser grain). CPU: the XLA client's thread lines.
            if gpu and not line.name.startswith("Stream"):
                continue
            if not gpu and not line.name.startswith("tf_XLA"):
                continue
            for ev in line.events:
                stats = {k: str(v) for k, v in ev.stats}
                if not gpu and "hlo_op" not in stats:
                    continue
                hlo_op = stats.get("hlo_op", "")
                texts = [ev.name, hlo_op, stats.get("tf_op", ""), names.get(hlo_op, "")]
                events.append(
                    {"name": ev.name, "dur_us": ev.duration_ns / 1e3, "part": _part(texts)}
                )
    return events


def profile_once(compiled, args, trace_dir: str) -> float:
    with jax.profiler.trace(trace_dir):
        t0 = time.perf_counter()
        jax.tree.map(lambda x: x.block_until_ready(), compiled(*args))
        return time.perf_counter() - t0


def profile_impl(config, data, fc_params, fwd, k: int, epochs: int) -> dict:
    timing, (compiled, args) = time_epochs(
        config, data, fc_params, fwd, 1, k, epochs, return_compiled=True
    )
    with tempfile.TemporaryDirectory() as tmp:
        wall_s = profile_once(compiled, args, tmp)
        events = device_kernels(tmp, op_names(compiled.as_text()))
    steps = epochs * (
        min(data.source.train.shape[0], data.constrained.train.shape[0]) // config.batch_size
    )
    by_part = collections.defaultdict(lambda: [0, 0.0])
    by_name = collections.defaultdict(lambda: [0, 0.0])
    for ev in events:
        by_part[ev["part"]][0] += 1
        by_part[ev["part"]][1] += ev["dur_us"]
        by_name[ev["name"]][0] += 1
        by_name[ev["name"]][1] += ev["dur_us"]
    busy_us = sum(ev["dur_us"] for ev in events)
    return {
        "impl": config.feedback_impl,
        "k": k,
        "epoch_s": timing["epoch_s"],
        "steps_profiled": steps,
        "profiled_wall_ms_per_step": 1e3 * wall_s / steps,
        "kernels_per_step": len(events) / steps,
        "busy_us_per_step": busy_us / steps,
        "parts": {
            p: {"kernels_per_step": n / steps, "busy_us_per_step": t / steps}
            for p, (n, t) in sorted(by_part.items(), key=lambda x: -x[1][1])
        },
        "top_kernels": [
            {"name": name[:120], "per_step": n / steps, "mean_us": t / n, "us_per_step": t / steps}
            for name, (n, t) in sorted(by_name.items(), key=lambda x: -x[1][1])[:25]
        ],
    }


def main(argv=None) -> None:
    parser = cli_parser("bench.profile_step", __doc__)
    parser.add_argument(
        "--out", default="runs/bench", help="output folder (committed results: bench/results)"
    )
    parser.add_argument("--data", default=None, help="babbling folder (default: synthetic)")
    parser.add_argument("--forward-c", default=None, help="trained F_c checkpoint")
    parser.add_argument("--k", type=int, default=10)
    parser.add_argument("--epochs", type=int, default=2)
    parser.add_argument(
        "--feedback-impls", nargs="+", default=["lean"], choices=config_lib.FEEDBACK_IMPLS
    )
    parser.add_argument("--tag", default="")
    args = parser.parse_args(argv)

    config = config_lib.TrainConfig()
    fwd = ForwardModel()
    data = babbling_data(Path(args.data), config) if args.data else synthetic_data(10, 600, config)
    fc_params = forward_c_params(fwd, args.forward_c)
    report = run_header("bench.profile_step", argv) | {"results": []}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = [
        f"# CCGAN-GP train step profile ({report['device']}, {report['cpu']})",
        "",
        f"Command: `{report['command']}`; jax {jax.__version__}; one seed, k = {args.k}, "
        f"{args.epochs} epochs profiled. Busy = sum of kernel durations; the rest of the wall "
        "time per step is the device idle between kernels.",
        "",
    ]
    for impl in args.feedback_impls:
        conf = dataclasses.replace(config, feedback_impl=train_lib.resolved_feedback_impl(impl))
        res = profile_impl(conf, data, fc_params, fwd, args.k, args.epochs)
        report["results"].append(res)
        print(json.dumps(res)[:2000], flush=True)
        lines += [
            f"## feedback {impl}: {res['epoch_s']:.3f} s / epoch, "
            f"{res['profiled_wall_ms_per_step']:.3f} ms / step profiled, "
            f"{res['kernels_per_step']:.0f} kernels / step, "
            f"{res['busy_us_per_step']:.0f} us busy / step",
            "",
            "| part | kernels / step | busy us / step |",
            "|---|---|---|",
        ]
        lines += [
            f"| {p} | {v['kernels_per_step']:.1f} | {v['busy_us_per_step']:.1f} |"
            for p, v in res["parts"].items()
        ]
        lines += ["", "| kernel | per step | mean us | us / step |", "|---|---|---|---|"]
        lines += [
            f"| `{t['name'][:70]}` | {t['per_step']:.1f} | {t['mean_us']:.2f} "
            f"| {t['us_per_step']:.1f} |"
            for t in res["top_kernels"][:12]
        ]
        lines.append("")
        (out / f"profile_step{args.tag}.json").write_text(json.dumps(report, indent=2))
        (out / f"profile_step{args.tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
