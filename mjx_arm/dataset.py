"""Babbling datasets: one `.npz` file per domain and split, written atomically, checked on load.

A file holds (no pickles; every field loads with ``allow_pickle=False``):

| key | shape, dtype | meaning |
|---|---|---|
| ``pressures_bar`` | [N, T, 3] float32 | chamber commands (bar) at 10 Hz |
| ``poses`` | [N, T, 6] float32 | tip position (m) then unit d3, read at the end of each command |
| ``pose_low``, ``pose_high`` | [6] float32 | per-axis task-space bounds for normalising to [0, 1] |
| ``meta`` | 0-d str | JSON: format, domain and its fields, model hash, seed, split, config |

Pressures normalise by the valve maximum (3.5 bar); poses by the per-axis bounds, which
`mjx_arm.babble` takes from the data of both domains (as in the paper), so one normaliser
serves both worlds.

A babbling run's files only make sense together (they share pose bounds), so `save_folder`
writes a folder as a whole: every file and a ``manifest.json`` (seed, config, pose bounds, model
hash, and each file's sha256) go into a temporary sibling folder that is renamed into place
at the end, replacing an earlier run's folder only then. A run killed part-way leaves the earlier
folder as it was, and its temporaries are removed by the next run. `load_dataset` checks a file
against its folder's manifest when there is one: a file the run did not write, a changed file,
or a folder missing some of the run's files is refused. Folders without a manifest (written
before it existed, or by hand) load file by file as before.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm import atomic, constants, run_folder
from mjx_arm.constants import N_CHAMBERS, POSE_DIM

#: Bumped when the file layout changes.
FORMAT_VERSION = 1
_ARRAY_KEYS = ("pressures_bar", "poses", "pose_low", "pose_high")
#: The file that names a run's files in its folder.
MANIFEST_NAME = "manifest.json"
#: Bumped when the manifest layout changes.
MANIFEST_FORMAT = 1


class DatasetError(ValueError):
    """A dataset file is unreadable, malformed, or was made with another model."""


class ModelHashMismatchError(DatasetError):
    """A dataset was simulated with a different MJCF than the caller expects."""


@dataclasses.dataclass(frozen=True)
class Dataset:
    """Babbling data of one domain and split.

    Attributes:
      pressures_bar: [N, T, 3] float32 chamber commands (bar), one per 0.1 s control period.
      poses: [N, T, 6] float32 tip position (m, world frame) then unit d3 director, at the end of
        each control period.
      pose_low, pose_high: [6] float32 per-axis task-space bounds (m for position, unitless for d3).
      domain: domain name ("source", "constrained", ...).
      domain_fields: the `mjx_arm.Domain` fields, as a dict.
      model_hash: `Arm.model_hash` of the MJCF the data was simulated with.
      seed: the babbling seed.
      split: "train", "val", or another label.
      control_hz: command and sampling rate (Hz).
      pressure_scale_bar: pressures are divided by this to normalise them (bar).
      config: the babbling options used, as a dict (informational).
    """

    pressures_bar: np.ndarray
    poses: np.ndarray
    pose_low: np.ndarray
    pose_high: np.ndarray
    domain: str
    domain_fields: dict[str, Any]
    model_hash: str
    seed: int
    split: str = "train"
    control_hz: float = constants.CONTROL_HZ
    pressure_scale_bar: float = constants.P_MAX_BAR
    config: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def n_trajectories(self) -> int:
        return int(self.pressures_bar.shape[0])

    @property
    def n_steps(self) -> int:
        return int(self.pressures_bar.shape[1])

    @property
    def duration_s(self) -> float:
        return self.n_steps / self.control_hz

    def normalised(self) -> tuple[np.ndarray, np.ndarray]:
        """Pressures [N, T, 3] and poses [N, T, 6] scaled to about [0, 1] (float32)."""
        return (
            normalise_pressure(self.pressures_bar, self.pressure_scale_bar),
            normalise_pose(self.poses, self.pose_low, self.pose_high),
        )

    def with_bounds(self, pose_low: np.ndarray, pose_high: np.ndarray) -> Dataset:
        """The same data with other task-space bounds ([6] each)."""
        return dataclasses.replace(
            self,
            pose_low=np.asarray(pose_low, np.float32),
            pose_high=np.asarray(pose_high, np.float32),
        )


# ---------------------------------------------------------------------------------- normalisation


def normalise_pressure(pressures_bar, scale_bar: float = constants.P_MAX_BAR) -> np.ndarray:
    """Pressures (bar) [..., 3] -> [..., 3] in [0, 1] for commands in [0, scale_bar]."""
    return (np.asarray(pressures_bar) / scale_bar).astype(np.float32)


def denormalise_pressure(pressures, scale_bar: float = constants.P_MAX_BAR) -> np.ndarray:
    """Inverse of `normalise_pressure`: [..., 3] -> bar."""
    return (np.asarray(pressures) * scale_bar).astype(np.float32)


def _span(low, high) -> np.ndarray:
    # A degenerate axis (e.g. one trajectory at rest) maps to 0 instead of dividing by zero.
    return np.maximum(np.asarray(high, np.float64) - np.asarray(low, np.float64), 1e-9)


def normalise_pose(poses, low, high) -> np.ndarray:
    """Poses [..., 6] -> [..., 6] in [0, 1] per axis within bounds low, high ([6] each)."""
    low = np.asarray(low, np.float64)
    return ((np.asarray(poses, np.float64) - low) / _span(low, high)).astype(np.float32)


def denormalise_pose(poses, low, high) -> np.ndarray:
    """Inverse of `normalise_pose`: [..., 6] in [0, 1] -> m (position) and unitless (d3)."""
    low = np.asarray(low, np.float64)
    return (np.asarray(poses, np.float64) * _span(low, high) + low).astype(np.float32)


def workspace_bounds(*poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis min and max over several pose arrays (e.g. both domains' data, as in the paper).

    Args:
      *poses: arrays [..., 6] (tip position in m, then d3).

    Returns:
      (low [6], high [6]) float32.
    """
    if not poses:
        raise ValueError("workspace_bounds needs at least one pose array")
    flat = np.concatenate([np.asarray(p, np.float64).reshape(-1, POSE_DIM) for p in poses])
    if flat.size == 0 or not np.isfinite(flat).all():
        raise ValueError("workspace_bounds needs non-empty, finite poses")
    return flat.min(0).astype(np.float32), flat.max(0).astype(np.float32)


# ---------------------------------------------------------------------------------- files


def _meta(ds: Dataset) -> dict[str, Any]:
    return {
        "format": FORMAT_VERSION,
        "domain": ds.domain,
        "domain_fields": ds.domain_fields,
        "model_hash": ds.model_hash,
        "seed": int(ds.seed),
        "split": ds.split,
        "control_hz": float(ds.control_hz),
        "pressure_scale_bar": float(ds.pressure_scale_bar),
        "config": ds.config,
    }


def save_dataset(path: str | os.PathLike, dataset: Dataset) -> Path:
    """Checks `dataset` and writes it to `path` atomically.

    The file is written to a temporary file in the same folder, flushed to disk, then renamed over
    `path`, so readers see the old file or the whole new one, never a partial one; on any error
    the temporary file is removed and an existing `path` is left as it was. Temporaries of
    `path` left by a killed process are removed.

    Returns:
      The path written.

    Raises:
      DatasetError: the dataset fails the checks `load_dataset` makes, or `path` is in a folder
        written as a whole by `save_folder` (one more file would mix runs: write a new folder).
    """
    path = Path(path)
    arrays = {
        "pressures_bar": np.asarray(dataset.pressures_bar, np.float32),
        "poses": np.asarray(dataset.poses, np.float32),
        "pose_low": np.asarray(dataset.pose_low, np.float32),
        "pose_high": np.asarray(dataset.pose_high, np.float32),
    }
    meta = _meta(dataset)
    _check(arrays, meta, str(path))
    if (path.parent / MANIFEST_NAME).exists():
        raise DatasetError(
            f"{path}: {path.parent} holds a whole babbling run ({MANIFEST_NAME}); adding or"
            " replacing one file would mix runs. Write the run to a new folder (`save_folder`)."
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic.remove_stale_temporaries(path)

    def write(f):
        np.savez(f, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)

    return atomic.write_atomically(path, write)


def load_dataset(path: str | os.PathLike, expected_model_hash: str | None = None) -> Dataset:
    """Loads and checks a dataset file.

    Args:
      path: a file written by `save_dataset` or `save_folder`.
      expected_model_hash: when given, the `Arm.model_hash` the data must have been made with.

    Returns:
      The `Dataset`.

    Raises:
      DatasetError: naming the file: it is missing or unreadable (truncated, corrupt, not a zip,
        any error of the zip or npy layers), has missing keys, wrong shapes or dtypes,
        non-finite values or bad metadata; or its folder has a manifest that the file does not
        match (not listed, changed, other seed or model) or that lists files the folder lacks
        or lacks files the folder has.
      ModelHashMismatchError: (a DatasetError) the model hash differs from `expected_model_hash`.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: no such dataset file")
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in (*_ARRAY_KEYS, "meta") if k not in npz.files]
            if missing:
                raise DatasetError(f"{path}: not a babbling dataset, missing keys {missing}")
            # Reading every member makes zipfile verify its CRC: corrupt bytes surface here.
            arrays = {k: npz[k] for k in _ARRAY_KEYS}
            meta_raw = npz["meta"]
    except DatasetError:
        raise
    except Exception as err:
        # Damaged bytes reach zipfile and numpy in many ways: besides BadZipFile and ValueError,
        # a flipped flag bit raises RuntimeError ("encrypted, password required") or
        # NotImplementedError (an unknown compression method), a flipped size MemoryError.
        raise DatasetError(
            f"{path}: unreadable or corrupt dataset file ({type(err).__name__}: {err})"
        ) from err
    try:
        meta = json.loads(str(meta_raw[()]))
        if not isinstance(meta, dict):
            raise TypeError("metadata is not an object")
    except Exception as err:
        raise DatasetError(f"{path}: bad metadata ({type(err).__name__}: {err})") from err
    _check(arrays, meta, str(path))
    if (path.parent / MANIFEST_NAME).exists():
        _check_membership(path, meta, arrays)
    if expected_model_hash is not None and meta["model_hash"] != expected_model_hash:
        raise ModelHashMismatchError(
            f"{path}: simulated with model {meta['model_hash']}, expected {expected_model_hash};"
            " regenerate it with `python -m mjx_arm.babble`"
        )
    return Dataset(
        pressures_bar=arrays["pressures_bar"],
        poses=arrays["poses"],
        pose_low=arrays["pose_low"],
        pose_high=arrays["pose_high"],
        domain=meta["domain"],
        domain_fields=dict(meta.get("domain_fields", {})),
        model_hash=meta["model_hash"],
        seed=int(meta["seed"]),
        split=meta["split"],
        control_hz=float(meta["control_hz"]),
        pressure_scale_bar=float(meta["pressure_scale_bar"]),
        config=dict(meta.get("config", {})),
    )


# ---------------------------------------------------------------------------------- folders


def sha256_file(path: Path) -> str:
    """The hex sha256 of a file, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def build_manifest(folder: str | os.PathLike) -> dict[str, Any]:
    """The manifest of the dataset files (``*.npz``) in `folder`, from the files alone.

    The run's id is a hash of the file names and contents, so the same files always give the
    same manifest (an earlier run's folder can get its manifest afterwards, exactly). With a
    manifest already there, every file is checked against it first (`load_dataset`).

    Returns:
      {"format", "id", "seed", "config", "model_hash", "pose_low", "pose_high", "files": {name:
      {"sha256", "bytes", "domain", "split", "n_trajectories", "n_steps"}}}; pose bounds as
      lists of 6 floats (float32 values).

    Raises:
      DatasetError: a file does not load, or the files are not one run: no files, or they
        differ in seed, config, model hash or pose bounds.
    """
    folder = Path(folder)
    files, runs = {}, {}
    for path in sorted(folder.glob("*.npz")):
        ds = load_dataset(path)
        files[path.name] = {
            "sha256": sha256_file(path),
            "bytes": path.stat().st_size,
            "domain": ds.domain,
            "split": ds.split,
            "n_trajectories": ds.n_trajectories,
            "n_steps": ds.n_steps,
        }
        runs[path.name] = {
            "seed": ds.seed,
            "config": ds.config,
            "model_hash": ds.model_hash,
            "pose_low": [float(x) for x in ds.pose_low],
            "pose_high": [float(x) for x in ds.pose_high],
        }
    if not files:
        raise DatasetError(f"{folder}: no dataset files (*.npz)")
    first = next(iter(runs.values()))
    for name, run in runs.items():
        differ = [key for key in first if run[key] != first[key]]
        if differ:
            raise DatasetError(
                f"{folder}: the files are not one babbling run: {name} differs from"
                f" {next(iter(runs))} in {differ}"
            )
    run_id = hashlib.sha256(
        "".join(f"{name}:{entry['sha256']}\n" for name, entry in files.items()).encode()
    ).hexdigest()[:16]
    return {"format": MANIFEST_FORMAT, "id": run_id, **first, "files": files}


def write_manifest(folder: str | os.PathLike) -> Path:
    """Writes `build_manifest(folder)` to ``folder/manifest.json`` atomically; returns its path."""
    folder = Path(folder)
    text = json.dumps(build_manifest(folder), indent=1, sort_keys=True) + "\n"
    return atomic.write_atomically(folder / MANIFEST_NAME, lambda f: f.write(text.encode()))


def read_manifest(folder: str | os.PathLike) -> dict[str, Any]:
    """The manifest of a run folder.

    Raises:
      DatasetError: it is missing, unreadable, or not a manifest of this format.
    """
    path = Path(folder) / MANIFEST_NAME
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
        files = manifest["files"]
        if manifest["format"] != MANIFEST_FORMAT or not isinstance(files, dict):
            raise ValueError(f"format {manifest['format']!r}, this code reads {MANIFEST_FORMAT}")
        keys = {"sha256", "bytes", "domain", "split"}
        if any(not isinstance(entry, dict) or keys - entry.keys() for entry in files.values()):
            raise ValueError(f"every file entry needs {sorted(keys)}")
    except Exception as err:
        raise DatasetError(f"{path}: unreadable manifest ({type(err).__name__}: {err})") from err
    return manifest


def _check_membership(path: Path, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    """Raises DatasetError unless `path` is, unchanged, one file of the complete run that its
    folder's manifest describes."""
    folder = path.parent
    manifest = read_manifest(folder)
    files = manifest["files"]
    entry = files.get(path.name)
    if entry is None:
        raise DatasetError(
            f"{path}: not a file of the run in {folder} (its {MANIFEST_NAME} lists"
            f" {sorted(files)}); the folder mixes runs"
        )
    present = {p.name for p in folder.glob("*.npz")}
    missing = sorted(set(files) - present)
    foreign = sorted(present - set(files))
    if missing or foreign:
        raise DatasetError(
            f"{path}: {folder} does not hold the run its {MANIFEST_NAME} describes:"
            f" missing {missing}, not of the run {foreign}; regenerate the folder"
        )
    # Every file, not only `path`: one swapped sibling of the same size would mix the run too.
    changed = [
        name
        for name, listed in files.items()
        if (folder / name).stat().st_size != listed["bytes"]
        or sha256_file(folder / name) != listed["sha256"]
    ]
    if changed:
        raise DatasetError(
            f"{path}: {changed} differ from the files the run in {folder} wrote (size or sha256);"
            " the folder mixes runs or was altered"
        )
    expected = {
        "domain": entry["domain"],
        "split": entry["split"],
        "seed": manifest.get("seed"),
        "model_hash": manifest.get("model_hash"),
    }
    wrong = [
        f"{key} {meta.get(key)!r} != {value!r}"
        for key, value in expected.items()
        if meta.get(key) != value
    ]
    bounds = np.asarray([manifest.get("pose_low"), manifest.get("pose_high")], np.float32)
    if not np.array_equal(bounds, np.stack([arrays["pose_low"], arrays["pose_high"]])):
        wrong.append("pose bounds")
    if wrong:
        raise DatasetError(f"{path}: does not match {folder / MANIFEST_NAME}: {'; '.join(wrong)}")


def save_folder(out_dir: str | os.PathLike, datasets: Mapping[str, Dataset]) -> list[Path]:
    """Writes one run's datasets as a whole folder: ``out_dir/<name>`` for each and a manifest.

    Everything is written into a temporary sibling folder, synced, and renamed into place at
    the end; an earlier `out_dir` is moved aside and removed only then. Killed at any point, the
    process leaves `out_dir` as it was (or, between the two renames, the earlier folder moved
    aside, which the next run puts back), never a mix; `atomic.remove_stale_temporaries` tidies up.

    Args:
      out_dir: the run's folder. If it exists it must be one `check_output_folder` accepts.
      datasets: file name (``*.npz``) -> dataset; all of one run (same seed, config, model hash
        and pose bounds).

    Returns:
      The dataset paths, in the order of `datasets`.

    Raises:
      DatasetError: a dataset fails its checks, or the datasets are not one run.
      FileExistsError, PermissionError: `out_dir` cannot hold a run (`check_output_folder`).
    """
    out_dir = Path(out_dir)
    bad = [name for name in datasets if Path(name).name != name or not name.endswith(".npz")]
    if bad or not datasets:
        raise DatasetError(f"need plain *.npz file names, got {list(datasets)}")
    check_output_folder(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    atomic.remove_stale_temporaries(out_dir)
    tmp = Path(
        tempfile.mkdtemp(prefix=atomic.temporary_prefix(out_dir), suffix=".tmp", dir=out_dir.parent)
    )
    try:
        os.chmod(tmp, 0o777 & ~atomic.umask())
        for name, ds in datasets.items():
            save_dataset(tmp / name, ds)
        write_manifest(tmp)
        atomic.fsync_dir(tmp)
        if out_dir.exists():
            old = Path(
                tempfile.mkdtemp(
                    prefix=atomic.temporary_prefix(out_dir), suffix=".old", dir=out_dir.parent
                )
            )
            os.replace(out_dir, old)
            try:
                os.replace(tmp, out_dir)
            except BaseException:
                os.replace(old, out_dir)  # the earlier run goes back
                raise
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out_dir)
        atomic.fsync_dir(out_dir.parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return [out_dir / name for name in datasets]


def check_output_folder(out_dir: str | os.PathLike) -> Path:
    """Checks, before any work, that `save_folder` may write (or replace) `out_dir`.

    A folder that exists must hold only what a run writes (``*.npz`` files, the manifest, and
    temporaries), since it is replaced as a whole; anything else would be deleted with it.

    Returns:
      `out_dir` as a Path.

    Raises:
      FileExistsError: `out_dir` is a file, or a folder holding other things (listed).
      PermissionError: the nearest existing folder on its path is not writable.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise FileExistsError(f"{out_dir} exists and is not a folder")
    if out_dir.is_dir():
        other = sorted(
            entry.name
            for entry in out_dir.iterdir()
            if not entry.is_file()
            or not (
                entry.name.endswith(".npz")
                or entry.name == MANIFEST_NAME
                or (entry.name.startswith(".") and entry.name.endswith(".tmp"))
            )
        )
        if other:
            raise FileExistsError(
                f"{out_dir} holds {other[:10]}, which are not babbling data; a run replaces its"
                " folder as a whole, so choose another folder or empty this one"
            )
    existing = out_dir.parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise FileExistsError(f"{existing} is not a folder, so {out_dir} cannot be made")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise PermissionError(f"cannot write in {existing}, so not {out_dir} either")
    run_folder.check_writable_folder(existing)  # a read-only mount, even for root
    return out_dir


def _check(arrays: dict[str, np.ndarray], meta: dict[str, Any], where: str) -> None:
    """Raises DatasetError unless arrays and metadata are consistent."""
    problems = []
    for key in _ARRAY_KEYS:
        if arrays[key].dtype != np.float32:
            problems.append(f"{key} has dtype {arrays[key].dtype}, expected float32")
    p, x = arrays["pressures_bar"], arrays["poses"]
    if p.ndim != 3 or p.shape[-1] != N_CHAMBERS:
        problems.append(f"pressures_bar has shape {p.shape}, expected [N, T, {N_CHAMBERS}]")
    elif x.shape != p.shape[:2] + (POSE_DIM,):
        problems.append(f"poses has shape {x.shape}, expected {p.shape[:2] + (POSE_DIM,)}")
    for key in ("pose_low", "pose_high"):
        if arrays[key].shape != (POSE_DIM,):
            problems.append(f"{key} has shape {arrays[key].shape}, expected ({POSE_DIM},)")
    for key in _ARRAY_KEYS:
        if arrays[key].dtype != np.float32:
            continue  # reported above; isfinite may not even apply to it
        n_bad = int(np.size(arrays[key]) - np.count_nonzero(np.isfinite(arrays[key])))
        if n_bad:
            problems.append(f"{key} has {n_bad} non-finite value(s)")
    if not problems and not (arrays["pose_low"] <= arrays["pose_high"]).all():
        problems.append("pose_low exceeds pose_high")
    if meta.get("format") != FORMAT_VERSION:
        problems.append(f"format {meta.get('format')!r}, this code reads {FORMAT_VERSION}")
    for key, kind in (
        ("domain", str),
        ("model_hash", str),
        ("split", str),
        ("seed", int),
        ("control_hz", float | int),
        ("pressure_scale_bar", float | int),
    ):
        if not isinstance(meta.get(key), kind):
            problems.append(f"metadata {key!r} missing or of the wrong type")
    for key in ("domain_fields", "config"):
        if not isinstance(meta.get(key, {}), dict):
            problems.append(f"metadata {key!r} is not an object")
    if problems:
        raise DatasetError(f"{where}: " + "; ".join(problems))
