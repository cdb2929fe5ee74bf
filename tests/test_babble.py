"""Babbling programs, sharded MJX rollouts, and dataset files, on a 3-segment model (CPU, small)."""

import mjx_arm  # noqa: I001  (before jax: it sets an XLA CPU flag)

import argparse
import dataclasses
import os
import re
import subprocess
import sys
import zipfile

import jax
import numpy as np
import pytest

from mjx_arm import atomic, babble, dataset
from mjx_arm.babble import cli as babble_cli
from mjx_arm.programs import babble_programs, shape_like_programs
from mjx_arm.dataset import DatasetError, ModelHashMismatchError

CONFIG = babble.BabbleConfig(n_train=3, n_val=1, duration_s=2.0, chunk=2, backend="c")


@pytest.fixture(scope="module")
def xml():
    return mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))


@pytest.fixture(scope="module")
def arm(xml):
    return mjx_arm.load(xml=xml, domain="source")


@pytest.fixture(scope="module")
def datasets(xml):
    """Both domains, train + val, MuJoCo C backend."""
    return babble.babble(CONFIG, xml=xml, progress=False)


# ---------------------------------------------------------------------------------- programs


def test_programs_shape_range_and_holds():
    config = babble.BabbleConfig(duration_s=30.0)
    p = babble_programs(config, np.arange(4))
    assert p.shape == (4, 300, 3) and p.dtype == np.float32
    assert p.min() >= 0.0 and p.max() <= mjx_arm.P_MAX_BAR
    # Each chamber holds a target for 5..30 control periods (the last hold may be cut by T).
    for chamber in p.transpose(0, 2, 1).reshape(-1, 300):
        switches = np.flatnonzero(np.diff(chamber) != 0) + 1
        runs = np.diff(np.concatenate([[0], switches]))
        assert runs.min() >= 5 and runs.max() <= 30
    # Chambers switch at different times (independent holds) and the cube is covered.
    assert not np.array_equal(np.diff(p[0, :, 0]) != 0, np.diff(p[0, :, 1]) != 0)
    assert p.min() < 0.5 and p.max() > 3.0


def test_programs_deterministic_per_seed_and_index():
    a = babble_programs(CONFIG, np.arange(5))
    np.testing.assert_array_equal(a, babble_programs(CONFIG, np.arange(5)))
    # Trajectory i does not depend on which others are drawn with it (chunking is invisible).
    np.testing.assert_array_equal(a[[4, 1]], babble_programs(CONFIG, [4, 1]))
    other_seed = babble_programs(dataclasses.replace(CONFIG, seed=1), np.arange(5))
    other_split = babble_programs(CONFIG, np.arange(5), split="val")
    other_domain = babble_programs(CONFIG, np.arange(5), domain="constrained")
    for b in (other_seed, other_split, other_domain):
        assert not np.array_equal(a, b)


def test_config_checks():
    with pytest.raises(ValueError):
        babble.BabbleConfig(backend="gpu")
    with pytest.raises(ValueError):
        babble.BabbleConfig(hold_min_s=2.0, hold_max_s=1.0)
    with pytest.raises(ValueError, match="distinct domains"):
        babble.BabbleConfig(domains=("source", "source"))
    with pytest.raises(ValueError, match="unknown domain 'sea'"):
        babble.BabbleConfig(domains=("source", "sea"))
    with pytest.raises(ValueError, match="seed must be >= 0"):
        babble.BabbleConfig(seed=-1)
    assert babble.PAPER.n_train == 50 and babble.PAPER.n_val == 3 and babble.PAPER.n_steps == 600


def test_auto_backend_is_c_on_cpu():
    assert jax.default_backend() == "cpu"
    assert babble.resolve_backend("auto") == "c"
    assert babble.resolve_backend("mjx") == "mjx"


# ---------------------------------------------------------------------------------- rollouts


def test_sharded_mjx_pads_and_agrees_with_c(arm, capsys):
    """One device: a 3-program batch padded to 4, against MuJoCo C; chunked run is identical."""
    programs = babble_programs(CONFIG, np.arange(3))
    sharded = babble.ShardedRollout(arm)
    assert sharded.n_devices == len(jax.devices()) == 1
    assert babble.padded_size(3, 1) == 3 and babble.padded_size(3, 2) == 4
    assert babble.padded_size(0, 4) == 4
    padded = sharded.pad(programs, 4)
    assert padded.shape == (4, CONFIG.n_steps, 3)
    np.testing.assert_array_equal(padded[3], programs[2])
    arr = sharded.shard(padded)
    assert arr.sharding.spec == jax.sharding.PartitionSpec("batch")

    poses, ok = sharded(programs, size=4)
    assert poses.shape == (3, CONFIG.n_steps, 6) and poses.dtype == np.float32 and ok.all()
    poses_c = babble.simulate(arm, programs, backend="c", chunk=2)
    np.testing.assert_allclose(poses, poses_c, atol=2e-5)
    # simulate() with chunks of 2 padded to 4 reuses the same compilation and gives the same data.
    chunked = babble.simulate(arm, programs, backend="mjx", chunk=4, sharded=sharded)
    np.testing.assert_allclose(chunked, poses, atol=1e-6)
    # The arm moves: babbling reaches well beyond rest.
    assert np.ptp(poses_c[..., :2]) > 5e-3
    # The one compile was announced on stderr before it ran, once.
    line = (
        f"compiling the sharded MJX rollout over 1 device(s) for batch 4 x {CONFIG.n_steps} steps"
    )
    assert capsys.readouterr().err.count(line) == 1


def test_diverged_trajectories_are_reported():
    ok = np.ones((3, 5), bool)
    ok[1, 2:] = False
    with pytest.raises(mjx_arm.SimulationDivergedError, match=r"\[11\]") as err:
        babble._raise_if_diverged(ok, offset=10)
    assert err.value.first_step.tolist() == [2]


# ---------------------------------------------------------------------------------- datasets


def test_babble_datasets_and_shared_bounds(datasets, arm):
    assert [(d.domain, d.split) for d in datasets] == [
        ("source", "train"),
        ("source", "val"),
        ("constrained", "train"),
        ("constrained", "val"),
    ]
    low, high = dataset.workspace_bounds(*(d.poses for d in datasets))
    for d in datasets:
        assert d.poses.shape == (d.n_trajectories, CONFIG.n_steps, 6)
        assert d.model_hash == arm.model_hash and d.seed == CONFIG.seed
        np.testing.assert_array_equal(d.pose_low, low)
        np.testing.assert_array_equal(d.pose_high, high)
        p, x = d.normalised()
        assert p.min() >= 0 and p.max() <= 1 and x.min() >= 0 and x.max() <= 1
    # Same programs in both domains? No: separate streams.
    assert not np.array_equal(datasets[0].pressures_bar, datasets[2].pressures_bar)
    # The constrained arm lags: its poses differ under babbling although statics agree.
    assert datasets[2].domain_fields["viscosity_scale"] == mjx_arm.CONSTRAINED.viscosity_scale


def test_normalise_round_trip():
    low = np.array([-1, -2, -3, -1, -1, -1], np.float32)
    high = np.array([1, 2, 3, 1, 1, 1], np.float32)
    x = np.array([[0, 0, 0, 0, 0, 0], [1, 2, 3, 1, 1, 1]], np.float32)
    # (0 - (-1)) / 2 = 0.5 on every axis; the upper bound maps to 1.
    np.testing.assert_allclose(dataset.normalise_pose(x, low, high), [[0.5] * 6, [1.0] * 6])
    np.testing.assert_allclose(
        dataset.denormalise_pose(dataset.normalise_pose(x, low, high), low, high), x
    )
    np.testing.assert_allclose(dataset.normalise_pressure([3.5, 1.75, 0.0]), [1.0, 0.5, 0.0])
    np.testing.assert_allclose(dataset.denormalise_pressure([1.0, 0.5]), [3.5, 1.75])


def test_run_writes_files_that_round_trip(datasets, tmp_path, xml, arm):
    d = datasets[0]
    path = dataset.save_dataset(tmp_path / "a.npz", d)
    back = dataset.load_dataset(path, expected_model_hash=arm.model_hash)
    for field in ("pressures_bar", "poses", "pose_low", "pose_high"):
        np.testing.assert_array_equal(getattr(back, field), getattr(d, field))
        assert getattr(back, field).dtype == np.float32
    assert (back.domain, back.split, back.seed, back.model_hash) == (
        "source",
        "train",
        0,
        d.model_hash,
    )
    assert back.domain_fields == d.domain_fields and back.config == d.config
    assert back.duration_s == pytest.approx(CONFIG.duration_s)
    assert sorted(os.listdir(tmp_path)) == ["a.npz"]  # no temporary left behind


def test_cli_writes_one_file_per_domain_and_split(tmp_path, xml, monkeypatch):
    model = tmp_path / "arm.xml"
    model.write_text(xml)
    argv = ["--domain", "source", "--n", "2", "--n-val", "1", "--duration", "1", "--seed", "3"]
    argv += ["--model", str(model), "--out", str(tmp_path / "out"), "--no-progress"]
    assert babble_cli.main(argv) == 0
    files = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert files == ["manifest.json", "source_train.npz", "source_val.npz"]
    d = dataset.load_dataset(tmp_path / "out" / "source_val.npz")
    assert d.pressures_bar.shape == (1, 10, 3) and d.seed == 3 and d.split == "val"
    expected = babble_programs(
        dataclasses.replace(CONFIG, seed=3, duration_s=1.0), [0], split="val"
    )
    np.testing.assert_array_equal(d.pressures_bar, expected)


def test_cli_babbles_shape_like_programs_in_unpaired_streams(tmp_path, xml):
    """--programs shape_like: each (domain, split) is its own shape_like_programs stream."""
    model = tmp_path / "arm.xml"
    model.write_text(xml)
    argv = ["--programs", "shape_like", "--n", "2", "--n-val", "1", "--duration", "1"]
    argv += ["--model", str(model), "--out", str(tmp_path / "out"), "--no-progress"]
    assert babble_cli.main(argv) == 0
    src = dataset.load_dataset(tmp_path / "out" / "source_train.npz")
    con = dataset.load_dataset(tmp_path / "out" / "constrained_train.npz")
    expected = shape_like_programs(2, 1.0, 0, split="babble/source/train")
    np.testing.assert_array_equal(src.pressures_bar, expected)
    assert not np.array_equal(src.pressures_bar, con.pressures_bar)
    assert src.config["programs"] == "shape_like"
    with pytest.raises(ValueError, match="programs must be one of"):
        babble.BabbleConfig(programs="shapes")


def test_load_refuses_mismatched_model_hash(datasets, tmp_path):
    path = dataset.save_dataset(tmp_path / "a.npz", datasets[0])
    with pytest.raises(ModelHashMismatchError, match="expected 0123"):
        dataset.load_dataset(path, expected_model_hash="0123")
    assert issubclass(ModelHashMismatchError, DatasetError)


def test_load_refuses_corrupt_files(datasets, tmp_path):
    good = dataset.save_dataset(tmp_path / "good.npz", datasets[0]).read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good[: len(good) // 2])
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"\x00garbage" * 100)
    # Flip bytes inside the poses payload: the zip still opens, the CRC check must catch it.
    flipped = bytearray(good)
    with zipfile.ZipFile(tmp_path / "good.npz") as z:
        info = z.getinfo("poses.npy")
    start = info.header_offset + 30 + len(info.filename) + 200
    flipped[start : start + 16] = bytes(16)
    bitrot = tmp_path / "bitrot.npz"
    bitrot.write_bytes(bytes(flipped))
    for path in (truncated, garbage, bitrot, tmp_path / "missing.npz"):
        with pytest.raises(DatasetError):
            dataset.load_dataset(path)


def test_load_refuses_bad_contents(datasets, tmp_path):
    d = datasets[0]
    nan = d.poses.copy()
    nan[0, 1, 2] = np.nan
    with pytest.raises(DatasetError, match="non-finite"):
        dataset.save_dataset(tmp_path / "x.npz", dataclasses.replace(d, poses=nan))
    # A file written by hand with a wrong shape and dtype is refused on load.
    np.savez(
        tmp_path / "bad.npz",
        pressures_bar=d.pressures_bar.astype(np.float64),
        poses=d.poses[:, :-1],
        pose_low=d.pose_low,
        pose_high=d.pose_high,
        meta=np.array("{}"),
    )
    with pytest.raises(DatasetError, match="dtype float64.*poses has shape"):
        dataset.load_dataset(tmp_path / "bad.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(DatasetError, match="missing keys"):
        dataset.load_dataset(tmp_path / "other.npz")


def test_atomic_write_leaves_no_partial_file(datasets, tmp_path, monkeypatch):
    path = tmp_path / "a.npz"
    dataset.save_dataset(path, datasets[0])
    before = path.read_bytes()

    def failing_savez(file, **arrays):
        file.write(b"PK\x03\x04 half a zip")
        raise OSError("disk full")

    monkeypatch.setattr(dataset.np, "savez", failing_savez)
    with pytest.raises(OSError, match="disk full"):
        dataset.save_dataset(path, datasets[1])
    with pytest.raises(OSError, match="disk full"):
        dataset.save_dataset(tmp_path / "new.npz", datasets[1])
    assert sorted(os.listdir(tmp_path)) == ["a.npz"]  # no temp file, no partial new file
    assert path.read_bytes() == before  # the old file is untouched


def test_two_devices_pad_shard_and_match_c(tmp_path, xml):
    """Two fake CPU devices (a fresh process): 3 programs padded to 4, split 2 + 2, same poses."""
    code = f"""
import dataclasses, numpy as np
import mjx_arm, jax
from mjx_arm import babble
from mjx_arm.programs import babble_programs, shape_like_programs
assert len(jax.devices()) == 2
arm = mjx_arm.load(xml=open({str(tmp_path / "arm.xml")!r}).read())
programs = babble_programs(babble.BabbleConfig(duration_s=1.0), np.arange(3))
sharded = babble.ShardedRollout(arm)
arr = sharded.shard(sharded.pad(programs))
assert arr.shape[0] == 4 and [s.data.shape[0] for s in arr.addressable_shards] == [2, 2]
poses = babble.simulate(arm, programs, backend="mjx", sharded=sharded)
np.testing.assert_allclose(poses, babble.simulate(arm, programs, backend="c"), atol=2e-5)
print("ok")
"""
    (tmp_path / "arm.xml").write_text(xml)
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]


def test_domain_flag_takes_both_or_a_list():
    both = babble_cli.config_from_args(babble_cli.parse_args(["--preset", "paper"]))
    assert both.domains == ("source", "constrained") and both.n_train == 50
    aged = babble_cli.config_from_args(
        babble_cli.parse_args(["--preset", "paper", "--domain", "source,aged"])
    )
    assert aged.domains == ("source", "aged") and aged.n_train == 50


def test_compilation_cache_is_on_for_accelerators_only(monkeypatch, tmp_path):
    from mjx_arm import machine

    before = jax.config.jax_compilation_cache_dir
    monkeypatch.delenv(machine.CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert jax.default_backend() == "cpu"
    assert machine.enable_compilation_cache() is None
    assert jax.config.jax_compilation_cache_dir == before
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    try:
        want = str(tmp_path / "softarm" / "jax")
        assert machine.enable_compilation_cache() == want
        assert jax.config.jax_compilation_cache_dir == want
        # A folder set in the environment is JAX's own business: returned, config untouched.
        jax.config.update("jax_compilation_cache_dir", before)
        monkeypatch.setenv(machine.CACHE_ENV, "/elsewhere")
        assert machine.enable_compilation_cache() == "/elsewhere"
        assert jax.config.jax_compilation_cache_dir == before
        # A folder given explicitly (`mjx_arm.babble --cache-dir`) applies on any backend.
        monkeypatch.setattr(jax, "default_backend", lambda: "cpu")
        assert machine.enable_compilation_cache(tmp_path / "mine") == str(tmp_path / "mine")
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "mine")
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


# ---------------------------------------------------------------------------------- whole folders

SMALL = babble.BabbleConfig(n_train=2, n_val=1, duration_s=1.0, domains=("source",), backend="c")


def _dead_pid() -> int:
    """The pid of a process that has exited (a killed writer's temporaries carry one)."""
    proc = subprocess.Popen([sys.executable, "-c", ""])
    proc.wait()
    return proc.pid


def _contents(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_run_replaces_its_folder_only_when_complete(tmp_path, xml, monkeypatch):
    """Killed while saving, a run leaves the earlier folder whole; the next run tidies up."""
    out = tmp_path / "out"
    babble.run(SMALL, out, xml=xml, progress=False)
    manifest = dataset.read_manifest(out)
    assert manifest["seed"] == 0 and sorted(manifest["files"]) == [
        "source_train.npz",
        "source_val.npz",
    ]
    before = _contents(out)

    saved = []

    def interrupted_save(path, ds):
        if saved:
            raise KeyboardInterrupt  # the second file: as a Ctrl-C while saving
        saved.append(path)
        return save(path, ds)

    save = dataset.save_dataset
    monkeypatch.setattr(dataset, "save_dataset", interrupted_save)
    with pytest.raises(KeyboardInterrupt):
        babble.run(dataclasses.replace(SMALL, seed=7), out, xml=xml, progress=False)
    monkeypatch.undo()
    assert saved and _contents(out) == before  # the earlier run, untouched
    assert os.listdir(tmp_path) == ["out"]  # and no temporary left beside it

    # A SIGKILL leaves temporaries behind: a half-written folder beside, a file inside (as the
    # file-by-file writer of old left them). Loading ignores them; the next run removes them.
    dead = _dead_pid()
    stale = tmp_path / f".out.{dead}.abc.tmp"
    stale.mkdir()
    (stale / "source_train.npz").write_bytes(before["source_train.npz"])
    (out / f".source_val.npz.{dead}.def.tmp").write_bytes(b"PK half a zip")
    assert dataset.load_dataset(out / "source_val.npz").seed == 0
    paths = babble.run(dataclasses.replace(SMALL, seed=7), out, xml=xml, progress=False)
    assert os.listdir(tmp_path) == ["out"]
    assert sorted(os.listdir(out)) == ["manifest.json", "source_train.npz", "source_val.npz"]
    assert [dataset.load_dataset(p).seed for p in paths] == [7, 7]
    # Killed between its two renames, a run leaves the earlier folder moved aside: put back.
    os.replace(out, tmp_path / f".out.{dead}.ghi.old")
    assert len(atomic.remove_stale_temporaries(out)) == 1 and os.listdir(tmp_path) == ["out"]
    assert dataset.load_dataset(out / "source_val.npz").seed == 7


def test_folder_refuses_a_mixed_or_partial_set(datasets, tmp_path):
    names = {f"{d.domain}_{d.split}.npz": d for d in datasets}
    a = dataset.save_folder(tmp_path / "a", names)[0].parent
    other = {name: dataclasses.replace(d, seed=7) for name, d in names.items()}
    b = dataset.save_folder(tmp_path / "b", other)[0].parent
    for name in names:
        assert dataset.load_dataset(a / name).seed == 0
    manifest = dataset.read_manifest(a)
    assert manifest["model_hash"] == datasets[0].model_hash and manifest["seed"] == 0
    np.testing.assert_array_equal(np.float32(manifest["pose_low"]), datasets[0].pose_low)

    # One file of another run (same size: only the seed differs) mixes the folder: every file
    # of it is refused, not only the foreign one.
    (a / "source_train.npz").write_bytes((b / "source_train.npz").read_bytes())
    for name in ("source_train.npz", "constrained_val.npz"):
        with pytest.raises(DatasetError, match=r"\['source_train.npz'\] differ"):
            dataset.load_dataset(a / name)
    (a / "source_train.npz").unlink()
    with pytest.raises(DatasetError, match=r"missing \['source_train.npz'\]"):
        dataset.load_dataset(a / "source_val.npz")
    (a / "source_train.npz").write_bytes((b / "source_train.npz").read_bytes())
    (b / "extra.npz").write_bytes((b / "source_val.npz").read_bytes())
    with pytest.raises(DatasetError, match=r"not of the run \['extra.npz'\]"):
        dataset.load_dataset(b / "source_val.npz")
    with pytest.raises(DatasetError, match="extra.npz: not a file of the run"):
        dataset.load_dataset(b / "extra.npz")
    (b / "extra.npz").unlink()
    with pytest.raises(DatasetError, match="would mix runs"):
        dataset.save_dataset(b / "source_val.npz", datasets[1])
    (b / "manifest.json").write_text('{"format": 1, "files": [')
    with pytest.raises(DatasetError, match="unreadable manifest"):
        dataset.load_dataset(b / "source_val.npz")
    # Datasets of different runs cannot make one folder; nothing is written.
    mixed = {"x.npz": datasets[0], "y.npz": dataclasses.replace(datasets[1], seed=7)}
    with pytest.raises(DatasetError, match=r"not one babbling run.*\['seed'"):
        dataset.save_folder(tmp_path / "c", mixed)
    assert sorted(os.listdir(tmp_path)) == ["a", "b"]


@pytest.mark.parametrize("folder", ["babble", "babble_aged"])
def test_committed_datasets_load_and_match_their_manifests(folder):
    """The committed folders' manifests are exactly what their files give (nothing invented)."""
    path = mjx_arm.constants.ROOT / "data" / folder
    manifest = dataset.read_manifest(path)
    assert dataset.build_manifest(path) == manifest
    for name, entry in manifest["files"].items():
        if name.endswith("_val.npz"):
            d = dataset.load_dataset(path / name, expected_model_hash=manifest["model_hash"])
            assert (d.domain, d.split, d.seed) == (entry["domain"], "val", 0)


def test_folders_without_a_manifest_load_file_by_file(datasets, tmp_path):
    path = dataset.save_dataset(tmp_path / "legacy" / "source_val.npz", datasets[1])
    (tmp_path / "legacy" / ".source_val.npz.123.tmp").write_bytes(b"stale")
    assert dataset.load_dataset(path).split == "val"


def test_every_damaged_bit_is_a_dataset_error(tmp_path):
    """Flip each bit of a small dataset file: it loads unchanged or raises DatasetError naming
    the file (zipfile alone raises RuntimeError, NotImplementedError, ... for some bits)."""
    rng = np.random.default_rng(0)
    d = dataset.Dataset(
        pressures_bar=rng.uniform(0, 3.5, (1, 2, 3)).astype(np.float32),
        poses=rng.uniform(-1, 1, (1, 2, 6)).astype(np.float32),
        pose_low=np.full(6, -1, np.float32),
        pose_high=np.ones(6, np.float32),
        domain="source",
        domain_fields={},
        model_hash="0" * 16,
        seed=0,
    )
    path = dataset.save_dataset(tmp_path / "flipped.npz", d)
    good = path.read_bytes()
    errors = {}
    fd = os.open(path, os.O_RDWR)  # flipped in place: rewriting the file is slow on some disks
    try:
        for bit in range(len(good) * 8):
            at = bit // 8
            os.pwrite(fd, bytes([good[at] ^ (1 << (bit % 8))]), at)
            try:
                back = dataset.load_dataset(path)
            except DatasetError as err:
                assert str(err).startswith(str(path)), err
                cause = type(err.__cause__).__name__
                errors[cause] = errors.get(cause, 0) + 1
                continue
            finally:
                os.pwrite(fd, good[at : at + 1], at)
            _assert_same(back, d)
    finally:
        os.close(fd)
    assert sum(errors.values()) > len(good) * 4  # most flips are caught
    assert {"RuntimeError", "NotImplementedError"} & set(errors)  # the ones that escaped before


def _assert_same(back, d):
    """A damaged file that still loads must hold the same data (the flip hit an unused or
    redundant field, e.g. a timestamp)."""
    np.testing.assert_array_equal(back.poses, d.poses)
    np.testing.assert_array_equal(back.pressures_bar, d.pressures_bar)
    assert (back.domain, back.seed, back.model_hash) == (d.domain, d.seed, d.model_hash)


# ---------------------------------------------------------------------------------- command line


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--chunk", "0"], "--chunk: .*must be >= 1"),
        (["--n", "-1"], "--n: .*must be >= 0"),
        (["--n-val", "-2"], "--n-val: .*must be >= 0"),
        (["--duration", "-1"], "--duration: .*> 0"),
        (["--duration", "nan"], "--duration: .*> 0"),
        (["--seed", "-1"], "--seed: .*must be >= 0"),
        (["--domain", "source,source"], "distinct domains"),
        (["--domain", "source,sea"], "unknown domain 'sea'"),
        (["--n", "0", "--n-val", "0"], "not both 0"),
        (["--hold-min", "2", "--hold-max", "1"], "hold_min_s <= hold_max_s"),
        (["--model", "no/such.xml"], "no such MJCF file"),
        (["--model", "{npz}"], "--model .*data.npz: .*(not an MJCF text file|does not parse)"),
        (["--model", "{negative}"], "--model .*negative.xml: .*timestep -0.004 s must be positive"),
        (["--distributed"], "--distributed needs a coordinator"),
        (["--out", "{file}"], "exists and is not a folder"),
        (["--out", "{busy}"], "notes.txt"),
    ],
)
def test_cli_refuses_bad_options_before_simulating(
    argv, message, tmp_path, monkeypatch, capsys, xml
):
    (tmp_path / "file").write_text("mine")
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine too")
    np.savez(tmp_path / "data.npz", poses=np.zeros((2, 3)))
    (tmp_path / "negative.xml").write_text(xml.replace('timestep="0.004"', 'timestep="-0.004"'))
    for name in babble_cli.COORDINATOR_ENV:
        monkeypatch.delenv(name, raising=False)
    paths = {k: tmp_path / v for k, v in [("file", "file"), ("busy", "busy"), ("npz", "data.npz")]}
    argv = [a.format(negative=tmp_path / "negative.xml", **paths) for a in argv]
    monkeypatch.setattr(babble.arm_lib, "load", lambda *a, **k: pytest.fail("loaded an arm"))
    monkeypatch.setattr(babble, "babble", lambda *a, **k: pytest.fail("simulated first"))
    with pytest.raises(SystemExit) as exit_:
        babble_cli.main(argv)
    assert exit_.value.code == 2  # an argparse usage error
    err = capsys.readouterr().err
    assert "usage: python -m mjx_arm.babble" in err and re.search(message, err), err
    assert (tmp_path / "file").read_text() == "mine"
    assert sorted(os.listdir(tmp_path / "busy")) == ["notes.txt"]


def test_cli_help_shows_every_option_with_its_default():
    parser = babble_cli.build_parser()
    text = " ".join(parser.format_help().split())
    assert parser.prog == "python -m mjx_arm.babble"
    for action in parser._actions:
        assert action.help, action.option_strings
        if action.default not in (None, argparse.SUPPRESS):
            assert f"(default: {action.default})" in text, action.option_strings
    assert "(default: 50)" in text and "(default: None)" not in text
