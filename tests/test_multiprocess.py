"""Two local JAX processes babble as one job and write what one process writes, bit for bit.

`python -m mjx_arm.babble --distributed` is the multi-host path (docs/multihost.md). Here two CPU
processes form one JAX job through a coordinator on 127.0.0.1 (gloo collectives), each with one
CPU device, so the MJX rollout's batch is sharded over both processes. The reference is one
process over two CPU devices (``--xla_force_host_platform_device_count=2``): the same global
mesh and per-device program, so any difference comes from the multi-process machinery. (Against
one process on ONE device, float32 poses differ by about an ulp, 2e-7: XLA's CPU code rounds
differently for other per-device batch sizes, e.g. 1 x 4 vs 2 x 2, though 1 x 8 and 2 x 4 agree.
That is XLA, not babbling.)

The run is tiny: a 3-segment arm, 2 + 1 trajectories of 2 s in one domain.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mjx_arm import ArmParams, generate_xml
from mjx_arm.babble import cli as babble_cli

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 150  # per process; the whole file takes ~25-50 s on 2 shared cores
FORCE_DEVICES = "--xla_force_host_platform_device_count"
#: Variables that would steer jax.distributed or the platform away from this test's settings.
JAX_ENV = (
    "JAX_COORDINATOR_ADDRESS",
    "JAX_COORDINATOR_PORT",
    "JAX_COORDINATOR_BIND_ADDRESS",
    "JAX_LOCAL_DEVICE_IDS",
    "JAX_CPU_COLLECTIVES_IMPLEMENTATION",
    "JAX_PLATFORMS",
    "JAX_COMPILATION_CACHE_DIR",
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env(n_devices: int) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in JAX_ENV}
    flags = [f for f in env.get("XLA_FLAGS", "").split() if not f.startswith(FORCE_DEVICES)]
    if n_devices > 1:
        flags.append(f"{FORCE_DEVICES}={n_devices}")
    env.update(XLA_FLAGS=" ".join(flags), JAX_PLATFORMS="cpu")
    return env


def _start(args: list[str], n_devices: int = 1) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "mjx_arm.babble", *args],
        cwd=ROOT,
        env=_env(n_devices),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _finish(procs: list[subprocess.Popen]) -> list[tuple[int, str, str]]:
    """Waits for every process (killing all of them past TIMEOUT_S); (rc, stdout, stderr)."""
    results = []
    try:
        for proc in procs:
            out, err = proc.communicate(timeout=TIMEOUT_S)
            results.append((proc.returncode, out, err))
    except subprocess.TimeoutExpired:
        for proc in procs:
            proc.kill()
        logs = [proc.communicate()[1][-2000:] for proc in procs]
        pytest.fail(f"a babbling process ran past {TIMEOUT_S} s; stderr tails: {logs}")
    return results


def _printed(stdout: str) -> list[str]:
    """stdout's lines, less gloo's "[Gloo] Rank i is connected to ..." notices."""
    return [line for line in stdout.splitlines() if line.strip() and not line.startswith("[Gloo]")]


def _distributed(common: list[str], out: Path, port: int, seeds=(0, 0)) -> list[list[str]]:
    return [
        [
            *common,
            "--seed",
            str(seed),
            "--out",
            str(out),
            "--distributed",
            "--coordinator",
            f"127.0.0.1:{port}",
            "--num-processes",
            "2",
            "--process-id",
            str(i),
        ]
        for i, seed in enumerate(seeds)
    ]


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("arm") / "arm3.xml"
    path.write_text(generate_xml(dataclasses.replace(ArmParams(), n_segments=3)))
    return path


def _common(model: Path) -> list[str]:
    return [
        *("--model", str(model), "--backend", "mjx", "--domain", "source"),
        *("--n", "2", "--n-val", "1", "--duration", "2", "--no-progress"),
    ]


def test_two_processes_write_what_one_process_writes(model, tmp_path):
    common = _common(model)
    one, two = tmp_path / "one", tmp_path / "two"
    # The reference and the two-process job run side by side (3 processes, 1 compile each).
    procs = [_start([*common, "--out", str(one)], n_devices=2)]
    procs += [_start(args) for args in _distributed(common, two, _free_port())]
    (rc_ref, out_ref, err_ref), (rc0, out0, err0), (rc1, out1, err1) = _finish(procs)
    assert rc_ref == 0, err_ref[-3000:]
    assert rc0 == 0 and rc1 == 0, f"process 0: {err0[-3000:]}\nprocess 1: {err1[-3000:]}"

    summary = json.loads(_printed(out0)[-1])
    assert (summary["processes"], summary["devices"]) == (2, 2), summary  # one job, 2 devices
    assert json.loads(_printed(out_ref)[-1])["devices"] == 2
    assert _printed(out1) == [], f"process 1 printed (only process 0 writes): {out1!r}"

    names = sorted(p.name for p in one.iterdir())
    assert names == ["manifest.json", "source_train.npz", "source_val.npz"], names
    assert sorted(p.name for p in two.iterdir()) == names  # nothing else, no temporaries
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one", "two"]
    for name in names:
        if (one / name).read_bytes() == (two / name).read_bytes():
            continue
        if name.endswith(".npz"):
            a, b = np.load(one / name), np.load(two / name)
            diffs = {
                k: float(np.abs(a[k].astype(float) - b[k].astype(float)).max())
                for k in a.files
                if k != "meta" and not np.array_equal(a[k], b[k])
            }
            pytest.fail(f"{name} differs from the one-process run; max |diff| by array: {diffs}")
        pytest.fail(f"{name} differs from the one-process run")


def test_processes_that_disagree_stop_before_simulating(model, tmp_path):
    procs = [
        _start(args)
        for args in _distributed(_common(model), tmp_path / "out", _free_port(), seeds=(0, 1))
    ]
    for rc, out, err in _finish(procs):
        assert rc != 0 and "processes disagree" in err, err[-3000:]
        assert _printed(out) == []
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--coordinator", "127.0.0.1:1234"], "--coordinator: only with --distributed"),
        (["--distributed", "--coordinator", "127.0.0.1"], "must be HOST:PORT"),
        (["--distributed", "--coordinator", "h:99999"], "must be HOST:PORT"),
        (["--distributed", "--process-id", "0"], "together"),
        (["--distributed", "--num-processes", "2", "--process-id", "2"], "must be < --num"),
        (["--distributed", "--num-processes", "0", "--process-id", "0"], "must be >= 1"),
    ],
)
def test_cli_refuses_bad_multiprocess_options(argv, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        babble_cli.parse_args([*argv, "--out", str(tmp_path / "out")])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err
