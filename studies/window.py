"""What the training window length changes: validation tracking error and time per epoch.

For each window length L, one CCGAN-GP seed is trained for `--epochs` epochs on the committed
paper data (every other setting at its default, F_c from `--forward-workdir`), then scored as
`ccgan.tune` scores a trial: the held-out tip error (cm) through F_c, best over the hold
factors k. Windows do not overlap, so an epoch has 600 / L windows per trajectory: short windows
mean more, cheaper steps; long windows let the LSTMs see more time per sample.

    python -m studies.window --epochs 10 --out studies/results/cpu

Writes window.md and window.json to --out.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import jax

from ccgan import data as data_lib
from ccgan import forward as forward_lib
from ccgan.cli import cli_parser
from ccgan.config import TrainConfig
from ccgan.train import load_npz
from ccgan.tune import ForwardCache, make_validation_run, validation_error_cm
from mjx_arm.machine import cpu_model

DATA = "data/babble"


def main(argv=None) -> dict:
    parser = cli_parser("studies.window", __doc__)
    parser.add_argument("--lengths", type=int, nargs="+", default=[5, 10, 20])
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--forward-workdir", default="results/solid/translators/ccgan")
    parser.add_argument(
        "--out",
        default="runs/studies",
        help="output folder (committed results: studies/results/cpu)",
    )
    args = parser.parse_args(argv)

    ps, xs, bounds = load_npz(f"{DATA}/source_train.npz", f"{DATA}/source_val.npz")
    pc, xc, _ = load_npz(f"{DATA}/constrained_train.npz", f"{DATA}/constrained_val.npz")
    forward = ForwardCache(forward_lib.ForwardConfig(), Path("/tmp"), args.forward_workdir)
    rows = []
    for length in args.lengths:
        config = dataclasses.replace(TrainConfig(), window_length=length, epochs=args.epochs)
        data = data_lib.prepare(ps, xs, pc, xc, length, config.n_val, config.stride, bounds=bounds)
        run = make_validation_run(config, data, forward(data, length))
        t0 = time.perf_counter()
        error, k, last = validation_error_cm(run, config)
        wall = time.perf_counter() - t0
        steps = data.source.train.shape[0] // config.batch_size
        rows.append(
            {
                "window_length": length,
                "steps_per_epoch": int(steps),
                "val_error_cm": error,
                "best_k": k,
                "wall_s_incl_compile": wall,
                "s_per_epoch_incl_compile": wall / args.epochs,
                "last_epoch": last,
            }
        )
        print(json.dumps(rows[-1]), flush=True)

    device = jax.devices()[0]
    header = [
        "# Window length: validation tracking error and time",
        "",
        f"Command: `python -m studies.window --epochs {args.epochs} --out {args.out}`; machine:"
        f" {cpu_model()}, JAX device {device.platform} ({device.device_kind}); one seed,"
        f" {args.epochs} epochs each on the committed paper data, other settings at their"
        " defaults; error = held-out tip error through F_c, best over k.",
        "",
        "| window L | steps / epoch | val error cm | best k | s / epoch (incl. compile) |",
        "|---|---|---|---|---|",
    ]
    lines = header + [
        f"| {r['window_length']} | {r['steps_per_epoch']} | {r['val_error_cm']:.3f} |"
        f" {r['best_k']} | {r['s_per_epoch_incl_compile']:.1f} |"
        for r in rows
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "window.md").write_text("\n".join(lines) + "\n")
    (out / "window.json").write_text(json.dumps({"epochs": args.epochs, "rows": rows}, indent=2))
    print("\n".join(lines))
    return {"rows": rows}


if __name__ == "__main__":
    main()
