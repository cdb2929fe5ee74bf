"""Summarises the GPU use that tools/device/chain.sh samples every 15 s (nvidia-smi's
"timestamp, utilization.gpu, memory.used" lines, one per GPU per sample, GPUs in a fixed order):
per GPU, the mean use and the share of samples under 10%.

    python tools/device/gpu_use.py results/paper/chain_2026-11-28/gpu_use_calls1-3.csv --gpus 2
"""

import argparse
import csv


def summary(path: str, gpus: int, idle_below: float = 10.0) -> list[str]:
    """One line per GPU: samples, mean use (%), share of samples under `idle_below` %."""
    rows = [r for r in csv.reader(open(path)) if len(r) >= 3]
    lines = []
    for gpu in range(gpus):
        use = [float(r[1].split()[0]) for r in rows[gpu::gpus]]
        idle = sum(u < idle_below for u in use) / len(use)
        lines.append(
            f"GPU {gpu}: {len(use)} samples, mean use {sum(use) / len(use):.1f}%,"
            f" under {idle_below:g}% in {100 * idle:.0f}% of them"
        )
    return lines


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv")
    parser.add_argument("--gpus", type=int, default=1, help="GPUs in each sample")
    args = parser.parse_args()
    print("\n".join(summary(args.csv, args.gpus)))
