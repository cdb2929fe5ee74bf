"""bench.throughput's result merging: runs made on different machines become one table."""

import json

import numpy as np

from bench import throughput


def _run(folder, impl, poses, machine=None):
    """Writes one run's json and check poses as `bench.throughput` does; returns the json path."""
    folder.mkdir()
    row = {
        "segments": 10,
        "nv": 40,
        "domain": "source",
        "impl": impl,
        "batch": 8,
        "mjx_compile_s": 1.0,
        "compile_shared": False,
        "mjx_first_call_s": 1.0,
        "mjx_wall_s": 0.5,
        "mjx_sim_s_per_s": {"jax": 100.0, "warp": 50.0}[impl],
        "mjx_steps_per_s": 1000,
        "c_sim_s_per_s": 10.0,
        "mjx_over_c": 10.0,
    }
    check = {
        "segments": 10,
        "domain": "source",
        "impl": impl,
        "programs": 2,
        "vs_c": {"pos_mm": 0.0, "d3": 0.0},
    }
    path = folder / "throughput_segments.json"
    doc = {"machine": machine or {}, "commands": [], "rows": [row], "checks": [check]}
    path.write_text(json.dumps(doc))
    np.savez(folder / "throughput_segments_check_poses.npz", **{f"seg10_source_{impl}": poses})
    return path


def test_merged_runs_check_warp_against_jax_poses_of_the_other_run(tmp_path):
    jax_poses = np.zeros((2, 3, 6))
    warp_poses = jax_poses.copy()
    warp_poses[1, 2, 0] = 0.002  # 2 mm at one control period
    jax_json = _run(tmp_path / "a", "jax", jax_poses)
    warp_json = _run(tmp_path / "b", "warp", warp_poses)

    results = throughput.Results(tmp_path / "merged", "_segments", {}, "", append=True)
    results.merge(warp_json)
    results.merge(jax_json)
    results.write()

    warp_check = next(c for c in results.checks if c["impl"] == "warp")
    assert warp_check["vs_jax"]["pos_mm"] == 2.0
    table = results.md_path.read_text()
    warp_row = next(line for line in table.splitlines() if "| 40 | source | MJX-Warp |" in line)
    assert warp_row.endswith("| 0.50 |")  # Warp / JAX throughput across the two runs


def test_each_row_keeps_the_machine_it_was_measured_on(tmp_path):
    """A report rewritten elsewhere (--report-only, --append) names the rows' machines, never
    the machine that rewrote it."""
    gpu = {"accelerator": "1 x NVIDIA H100", "backend": "gpu", "cpu": "Xeon", "cpu_cores": 16}
    other = {"accelerator": "1 x NVIDIA H200", "backend": "gpu", "cpu": "Xeon", "cpu_cores": 16}
    laptop = {"accelerator": "1 x cpu", "backend": "cpu", "cpu": "EPYC", "cpu_cores": 2}
    jax_json = _run(tmp_path / "a", "jax", np.zeros((2, 3, 6)), gpu)
    warp_json = _run(tmp_path / "b", "warp", np.zeros((2, 3, 6)), other)

    one = throughput.Results(tmp_path / "one", "_segments", laptop, "", append=True)
    one.merge(jax_json)
    one.write()
    assert [r["machine"] for r in one.rows] == [gpu]
    text = one.md_path.read_text()
    assert "Machine: 1 x NVIDIA H100 (gpu), CPU Xeon x 16 cores" in text and "EPYC" not in text
    assert "16 threads" in text

    both = throughput.Results(tmp_path / "one", "_segments", laptop, "", append=True)
    both.merge(warp_json)
    both.write()
    stored = json.loads(both.json_path.read_text())
    assert stored["machines"] == [gpu, other] and "EPYC" not in both.md_path.read_text()
    assert "- 1 x NVIDIA H200 (gpu)" in both.md_path.read_text()
    # A row this run measures (no machine of its own) carries this run's machine.
    measured = {k: v for k, v in stored["rows"][0].items() if k != "machine"} | {"batch": 16}
    both.add_row(measured, write=False)
    assert next(r for r in both.rows if r["batch"] == 16)["machine"] == laptop
