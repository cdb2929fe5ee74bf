"""Wall time of CCGAN-GP training: compile time and seconds per epoch, one seed and vmapped seeds.

Synthetic data of the paper's shapes (pressures [N, T, 3] bar, smooth poses [N, T, 6]) and a
randomly initialised F_c (64/50): the cost of a train step does not depend on the values. Each
timing forces every seed's k to one value of `hold_factors`; the k selection (every
`stretch_every` epochs) is timed on its own and amortised into the per-epoch figure.

    python -m bench.train --out bench/results                 # reduced config (CPU)
    python -m bench.train --paper --out bench/results/h200    # paper scale, 550 epochs (GPU)

Writes train.md and train.json (train_paper.* with --paper) to --out.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from bench import parse_checked, run_header
from ccgan import checkpoint
from ccgan import config as config_lib
from ccgan import data as data_lib
from ccgan import train as train_lib
from ccgan.cli import cli_parser
from ccgan.models import ForwardModel
from mjx_arm.programs import random_held_programs

#: The paper's training time for one CCGAN-GP (12 h 32 min).
PAPER_WALL_S = 12 * 3600 + 32 * 60


def synthetic_data(n_traj: int, samples: int, config: config_lib.TrainConfig, seed: int = 0):
    """Both domains: n_traj trajectories x samples steps, random held pressures, smooth poses."""
    rng = np.random.default_rng(seed)
    arrays = []
    for _ in range(2):
        p = random_held_programs(rng, n_traj, samples)
        x = np.cumsum(rng.normal(scale=0.01, size=(n_traj, samples, 6)), axis=1)
        arrays += [p, x.astype(np.float32)]
    return data_lib.prepare(*arrays, config.window_length, config.n_val, config.stride)


def forward_c_params(fwd: ForwardModel, path: str | None):
    """F_c parameters: the checkpoint at `path`, else a fresh init (seed 1) of `fwd`."""
    params = fwd.init(jax.random.PRNGKey(1), jnp.zeros((1, 1, 6)), jnp.zeros((1, 1, 3)))
    return checkpoint.load(path, target=params)[0] if path else params


def babbling_data(folder: Path, config: config_lib.TrainConfig):
    """Windows of a babbling folder, prepared as `python -m ccgan.train` does."""
    split = lambda d: [folder / f"{d}_{s}.npz" for s in ("train", "val")]  # noqa: E731
    ps, xs, bounds = train_lib.load_npz(*split("source"))
    pc, xc, _ = train_lib.load_npz(*split("constrained"))
    return data_lib.prepare(
        ps, xs, pc, xc, config.window_length, config.n_val, config.stride, bounds=bounds
    )


def _block(tree):
    return jax.tree.map(lambda x: x.block_until_ready(), tree)


def time_epochs(
    config, data, fc_params, fwd, n_seeds: int, k: int, epochs: int, return_compiled: bool = False
):
    """Compile time and seconds per epoch of `run_epochs` for n_seeds vmapped seeds at hold k.

    Returns the timings dict, and with `return_compiled` also (compiled run, its arguments), so a
    caller can run the same executable again without compiling it twice.
    """
    trainer = train_lib.make_trainer(config, data, fc_params, fwd)
    keys = jax.random.split(jax.random.PRNGKey(0), n_seeds)
    state = _block(jax.jit(jax.vmap(trainer.init))(keys))
    state = state.replace(k=jnp.full_like(state.k, k))
    run = jax.jit(jax.vmap(trainer.run_epochs, in_axes=(0, 0, None, None)), static_argnums=3)
    # Epochs 0..epochs-1 with epochs < stretch_every never reach the k selection.
    t0 = time.perf_counter()
    compiled = run.lower(state, keys, jnp.int32(0), epochs).compile()
    compile_s = time.perf_counter() - t0
    _block(compiled(state, keys, jnp.int32(0)))  # warm-up
    t0 = time.perf_counter()
    out_state, _ = _block(compiled(state, keys, jnp.int32(0)))
    epoch_s = (time.perf_counter() - t0) / epochs
    assert np.all(np.asarray(out_state.k) == k), "k changed inside the timed epochs"

    val = jax.jit(jax.vmap(trainer.validation_errors))
    t0 = time.perf_counter()
    val_compiled = val.lower(state).compile()
    val_compile_s = time.perf_counter() - t0
    _block(val_compiled(state))
    reps = 3
    t0 = time.perf_counter()
    for _ in range(reps):
        _block(val_compiled(state))
    select_s = (time.perf_counter() - t0) / reps
    timings = {
        "seeds": n_seeds,
        "k": k,
        "compile_s": compile_s,
        "epoch_s": epoch_s,
        "select_compile_s": val_compile_s,
        "select_s": select_s,
        "epoch_with_select_s": epoch_s + select_s / config.stretch_every,
    }
    if return_compiled:
        return timings, (compiled, (state, keys, jnp.int32(0)))
    return timings


def run_paper_to_workdir(config, data, fc_params, fwd, seeds, workdir: Path) -> dict:
    """The whole run through `train_and_evaluate` (checkpoints, CSV log, translator files)."""
    t_start = time.perf_counter()
    state, rows = train_lib.train_and_evaluate(
        config, data, fc_params, workdir, seeds=seeds, forward_model=fwd, resume=False
    )
    total_s = time.perf_counter() - t_start
    last = [r for r in rows if r["epoch"] == config.epochs]
    val = [r["val_error_cm"] for r in rows if np.isfinite(r["val_error_cm"])]
    return {
        "seeds": list(seeds),
        "epochs": config.epochs,
        "compile_s": float("nan"),
        "total_s": total_s,
        "epoch_s": total_s / config.epochs,
        "k_final": [int(r["k"]) for r in last],
        "val_error_cm_final": [r["val_error_cm"] for r in last],
        "val_error_cm_best": min(val) if val else None,
        "workdir": str(workdir),
        "paper_s": PAPER_WALL_S,
    }


def run_paper(config, data, fc_params, fwd, seeds: tuple[int, ...]) -> dict:
    """The whole run, chunked like `train_and_evaluate` (no files): total wall time."""
    trainer = train_lib.make_trainer(config, data, fc_params, fwd)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds))
    t_start = time.perf_counter()
    state = _block(jax.jit(jax.vmap(trainer.init))(keys))
    run = jax.jit(jax.vmap(trainer.run_epochs, in_axes=(0, 0, None, None)), static_argnums=3)
    chunk = max(1, config.checkpoint_every)
    compiled = run.lower(state, keys, jnp.int32(0), chunk).compile()
    compile_s = time.perf_counter() - t_start
    ks = []
    for start in range(0, config.epochs, chunk):
        n = min(chunk, config.epochs - start)
        fn = compiled if n == chunk else run
        args = (state, keys, jnp.int32(start)) if n == chunk else (state, keys, jnp.int32(start), n)
        state, metrics = _block(fn(*args))
        ks.append(np.asarray(metrics["k"])[:, -1].tolist())
        print(f"epoch {start + n}: {time.perf_counter() - t_start:.1f} s, k {ks[-1]}", flush=True)
    total_s = time.perf_counter() - t_start
    return {
        "seeds": list(seeds),
        "epochs": config.epochs,
        "compile_s": compile_s,
        "total_s": total_s,
        "epoch_s": (total_s - compile_s) / config.epochs,
        "k_per_chunk": ks,
        "paper_s": PAPER_WALL_S,
    }


def _hms(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600} h {s % 3600 // 60:02d} min {s % 60:02d} s"


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m bench.train`` (the module docstring is its help)."""
    parser = cli_parser("bench.train", __doc__)
    parser.add_argument(
        "--out", default="runs/bench", help="output folder (committed results: bench/results)"
    )
    parser.add_argument("--paper", action="store_true", help="paper scale, 550 epochs, end to end")
    parser.add_argument("--n-traj", type=int, default=10, help="trajectories per domain")
    parser.add_argument("--samples", type=int, default=600, help="control steps per trajectory")
    parser.add_argument("--epochs", type=int, default=3, help="timed epochs (< stretch_every)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 3], help="vmapped seed counts")
    parser.add_argument("--k", type=int, nargs="+", default=None, help="hold factors timed")
    parser.add_argument("--paper-seeds", type=int, default=1, help="seeds of the --paper run")
    parser.add_argument("--paper-epochs", type=int, default=550, help="epochs of the --paper run")
    parser.add_argument("--tag", default="", help="suffix of the output file names")
    parser.add_argument(
        "--data",
        default=None,
        help="babbling folder ({source,constrained}_{train,val}.npz) instead of synthetic data",
    )
    parser.add_argument(
        "--forward-c", default=None, help="trained F_c checkpoint (default: random F_c)"
    )
    parser.add_argument(
        "--feedback-unroll", type=int, default=None, help="TrainConfig.feedback_unroll"
    )
    parser.add_argument(
        "--workdir",
        default=None,
        help="--paper: train through train_and_evaluate into this folder (files included)",
    )
    parser.add_argument(
        "--feedback-impls",
        nargs="+",
        default=[config_lib.TrainConfig.feedback_impl],
        choices=config_lib.FEEDBACK_IMPLS,
        help="feedback rollout implementations timed (TrainConfig.feedback_impl)",
    )
    return parser


def bench_data(args: argparse.Namespace, config: config_lib.TrainConfig):
    """The timed data: the babbling folder `--data`, else synthetic data (50 + n_val
    trajectories per domain with --paper, else --n-traj).

    Returns:
      (prepared `TranslationData`, trajectories per domain, samples (control steps) per
      trajectory: the folder's own with --data, else --samples).
    """
    if args.data:
        data = babbling_data(Path(args.data), config)
        samples = data.source.val.shape[1]
        n_traj = data.source.train.shape[0] * config.stride // samples + config.n_val
    else:
        samples = args.samples
        n_traj = 50 + config.n_val if args.paper else args.n_traj
        data = synthetic_data(n_traj, samples, config)
    return data, n_traj, samples


def paper_section(args, config, data, fc_params, fwd, report: dict) -> list[str]:
    """Times the whole --paper run (through `train_and_evaluate` with --workdir); records it in
    `report` as "paper_run" and returns its markdown lines."""
    seeds = tuple(range(args.paper_seeds))
    if args.workdir:
        res = run_paper_to_workdir(config, data, fc_params, fwd, seeds, Path(args.workdir))
    else:
        res = run_paper(config, data, fc_params, fwd, seeds)
    res["feedback"] = config.feedback_impl
    report["paper_run"] = res
    lines = [
        "| feedback | seeds | epochs | compile (s) | s / epoch | total | paper (PyTorch) |",
        "|---|---|---|---|---|---|---|",
        f"| {res['feedback']} | {len(seeds)} | {res['epochs']} "
        f"| {'in total' if np.isnan(res['compile_s']) else format(res['compile_s'], '.1f')} "
        f"| {res['epoch_s']:.3f} "
        f"| {_hms(res['total_s'])} | {_hms(PAPER_WALL_S)} |",
    ]
    if args.workdir:
        lines += [
            "",
            f"Through `train_and_evaluate` (checkpoints, CSV, translator files; compile "
            f"included in the total): final k {res['k_final']}, validation tracking error "
            f"(through F_c) {res['val_error_cm_final']} cm at the end, best "
            f"{res['val_error_cm_best']} cm.",
        ]
    return lines


def timings_section(args, config, data, fc_params, fwd, report: dict) -> list[str]:
    """Times `--epochs` epochs for every feedback implementation, seed count and k; records
    the rows in `report` as "timings" and returns their markdown lines."""
    ks = args.k or [min(config.hold_factors), max(config.hold_factors)]
    rows = []
    for impl in args.feedback_impls:
        conf = dataclasses.replace(config, feedback_impl=impl)
        for n_seeds in args.seeds:
            for k in ks:
                r = time_epochs(conf, data, fc_params, fwd, n_seeds, k, args.epochs)
                r["feedback"] = impl
                rows.append(r)
                print(json.dumps(r), flush=True)
    report["timings"] = rows
    lines = [
        "| feedback | seeds | k | compile (s) | s / epoch | k selection (s) "
        "| s / epoch incl. selection |",
        "|---|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {r['feedback']} | {r['seeds']} | {r['k']} | {r['compile_s']:.1f} "
        f"| {r['epoch_s']:.3f} "
        f"| {r['select_s']:.3f} | {r['epoch_with_select_s']:.3f} |"
        for r in rows
    ]
    return lines


def main(argv=None) -> None:
    """Runs ``python -m bench.train`` with `argv` (default: sys.argv[1:]); writes
    ``<out>/<name>.json`` and ``.md`` (name: train or train_paper, then --tag)."""
    args = parse_checked(build_parser(), argv, prefix=False)
    args.feedback_impls = [train_lib.resolved_feedback_impl(i) for i in args.feedback_impls]

    # The GPU step alone: k through F_c every 10 epochs inside the jitted epoch, as when the
    # committed timings were taken (the simulator's choice runs on the host; ccgan_study times it).
    config = config_lib.TrainConfig(
        feedback_impl=args.feedback_impls[0],
        epochs=args.paper_epochs,
        k_choice="forward",
        stretch_every=10,
    )
    if args.feedback_unroll:
        config = dataclasses.replace(config, feedback_unroll=args.feedback_unroll)
    fwd = ForwardModel()
    data, n_traj, samples = bench_data(args, config)
    fc_params = forward_c_params(fwd, args.forward_c)
    steps = min(data.source.train.shape[0], data.constrained.train.shape[0]) // config.batch_size
    report = run_header("bench.train", argv) | {
        "n_devices": jax.device_count(),
        "trajectories_per_domain": n_traj,
        "samples": samples,
        "train_windows": int(data.source.train.shape[0]),
        "steps_per_epoch": steps,
        "config": config.to_dict(),
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = [
        f"# CCGAN-GP training time ({report['device']} x {report['n_devices']}, {report['cpu']})",
        "",
        f"{n_traj} trajectories x {samples} samples per domain ({config.n_val} held out), "
        f"window {config.window_length}, batch {config.batch_size}: {steps} steps per epoch; "
        f"feedback rollout {config.feedback_impl}, {config.feedback_unroll} periods per loop "
        f"iteration; jax {jax.__version__}. Command: `{report['command']}`.",
        "",
    ]
    section = paper_section if args.paper else timings_section
    lines += section(args, config, data, fc_params, fwd, report)
    name = ("train_paper" if args.paper else "train") + args.tag
    (out / f"{name}.json").write_text(json.dumps(report, indent=2))
    (out / f"{name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
