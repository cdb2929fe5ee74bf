"""Every benchmark checks --out before any work: an --out under a file is a usage error (exit 2)
naming --out, not a traceback after minutes of timings."""

import importlib

import pytest

#: (module, whether --out is a prefix of .md/.json files rather than a folder)
BENCHES = [
    ("bench.c_chunk_memory", True),
    ("bench.compile_cache", True),
    ("bench.distill_step", True),
    ("bench.sharing", True),
    ("bench.step_latency", True),
    ("bench.teacher", True),
    ("bench.train", False),
    ("bench.rod_throughput", False),
]


@pytest.mark.parametrize("module, prefix", BENCHES)
def test_a_bench_refuses_an_out_it_cannot_write_before_any_work(module, prefix, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    bench = importlib.import_module(module)
    with pytest.raises(SystemExit) as stop:
        bench.main(["--out", str(blocker / "results")])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "--out" in err and str(blocker) in err


def test_a_writable_prefix_passes(tmp_path):
    from bench import parse_checked
    from ccgan.cli import cli_parser

    p = cli_parser("bench.x", "doc")
    p.add_argument("--out", required=True)
    assert parse_checked(p, ["--out", str(tmp_path / "new" / "x")]).out.endswith("x")
