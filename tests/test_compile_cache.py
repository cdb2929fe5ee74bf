"""The persistent JAX compilation cache: on by default, moved or turned off by SOFTARM_JAX_CACHE.

mjx_arm sets the cache when it is imported, so each case imports it in a fresh process.
"""

import json
import os
import subprocess
import sys

import pytest

PROBE = """
import json, os
import jax
import mjx_arm
f = jax.jit(lambda x: x * 2.0 + 1.0)
f(jax.numpy.ones(3)).block_until_ready()
print(json.dumps({
    "dir": jax.config.jax_compilation_cache_dir,
    "package_dir": mjx_arm.COMPILATION_CACHE_DIR,
    "min_compile_time_s": jax.config.jax_persistent_cache_min_compile_time_secs,
}))
"""


def _run_probe(tmp_path, **env_changes) -> subprocess.CompletedProcess:
    """Imports mjx_arm in a fresh process with HOME and XDG_CACHE_HOME under tmp_path, in
    tmp_path / "cwd"."""
    ours = ("SOFTARM_JAX_CACHE", "JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_")
    env = {k: v for k, v in os.environ.items() if not k.startswith(ours)}
    env.update(HOME=str(tmp_path / "home"), XDG_CACHE_HOME=str(tmp_path / "xdg"))
    for key, value in env_changes.items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value
    cwd = tmp_path / "cwd"
    cwd.mkdir(exist_ok=True)
    return subprocess.run(
        [sys.executable, "-c", PROBE], env=env, cwd=cwd, capture_output=True, text=True, timeout=300
    )


def _probe(tmp_path, **env_changes) -> dict:
    out = _run_probe(tmp_path, **env_changes)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_on_by_default_in_the_xdg_cache_folder(tmp_path):
    got = _probe(tmp_path)
    assert got["dir"] == str(tmp_path / "xdg" / "softarm-ccgan" / "jax")
    assert got["package_dir"] == got["dir"]
    assert got["min_compile_time_s"] == pytest.approx(1.0)


def test_home_cache_without_xdg(tmp_path):
    got = _probe(tmp_path, XDG_CACHE_HOME=None)
    assert got["dir"] == str(tmp_path / "home" / ".cache" / "softarm-ccgan" / "jax")


@pytest.mark.parametrize("off", ["0", "off"])
def test_variable_turns_it_off(tmp_path, off):
    got = _probe(tmp_path, SOFTARM_JAX_CACHE=off)
    assert got["dir"] is None and got["package_dir"] is None
    assert not (tmp_path / "xdg" / "softarm-ccgan").exists()


def test_variable_moves_it_and_a_compile_writes_there(tmp_path):
    where = tmp_path / "elsewhere"
    # JAX's own threshold variable wins over the package's, so the tiny program is written.
    got = _probe(
        tmp_path, SOFTARM_JAX_CACHE=str(where), JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0"
    )
    assert got["dir"] == str(where)
    assert got["min_compile_time_s"] == 0.0
    assert any(p.name.endswith("-cache") for p in where.iterdir())
    assert not (tmp_path / "xdg" / "softarm-ccgan").exists()


def test_jax_own_setting_is_left_alone(tmp_path):
    got = _probe(tmp_path, JAX_COMPILATION_CACHE_DIR=str(tmp_path / "jax_own"))
    assert got["dir"] == str(tmp_path / "jax_own")


def test_tilde_expands_to_home(tmp_path):
    got = _probe(tmp_path, SOFTARM_JAX_CACHE="~/jaxcache")
    assert got["dir"] == str(tmp_path / "home" / "jaxcache")


def test_unknown_user_is_refused_and_makes_no_folder_in_the_working_directory(tmp_path):
    out = _run_probe(tmp_path, SOFTARM_JAX_CACHE="~nosuchuser/x")
    assert out.returncode != 0
    assert "SOFTARM_JAX_CACHE='~nosuchuser/x'" in out.stderr and "names no user" in out.stderr
    assert list((tmp_path / "cwd").iterdir()) == []


def test_unwritable_folder_is_refused(tmp_path):
    (tmp_path / "a_file").write_text("")
    out = _run_probe(tmp_path, SOFTARM_JAX_CACHE=str(tmp_path / "a_file" / "jax"))
    assert out.returncode != 0
    assert "not a writable folder" in out.stderr.splitlines()[-1]


def test_tests_run_with_the_cache_off(monkeypatch):
    """conftest's SOFTARM_JAX_CACHE=0 reached the package: no cache folder in this process, and
    the same reading of the variable gives a folder once it is on."""
    import jax

    import mjx_arm

    assert jax.config.jax_compilation_cache_dir is None
    assert mjx_arm.COMPILATION_CACHE_DIR is None
    assert mjx_arm._compilation_cache_dir() is None
    monkeypatch.setenv("SOFTARM_JAX_CACHE", "on")
    monkeypatch.setenv("XDG_CACHE_HOME", "/xdg")
    assert mjx_arm._compilation_cache_dir() == "/xdg/softarm-ccgan/jax"
