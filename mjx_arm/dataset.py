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
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm import constants

#: Bumped when the file layout changes.
FORMAT_VERSION = 1
POSE_DIM = 6
N_CHAMBERS = 3
_ARRAY_KEYS = ("pressures_bar", "poses", "pose_low", "pose_high")


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
    the temporary file is removed and an existing `path` is left as it was.

    Returns:
      The path written.

    Raises:
      DatasetError: the dataset fails the checks `load_dataset` makes.
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
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600 files; honour the umask instead
        with os.fdopen(fd, "wb") as f:
            np.savez(f, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def load_dataset(path: str | os.PathLike, expected_model_hash: str | None = None) -> Dataset:
    """Loads and checks a dataset file.

    Args:
      path: a file written by `save_dataset`.
      expected_model_hash: when given, the `Arm.model_hash` the data must have been made with.

    Returns:
      The `Dataset`.

    Raises:
      DatasetError: the file is missing, truncated, corrupt (bad zip or CRC), has missing keys,
        wrong shapes or dtypes, non-finite values, or bad metadata.
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
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, KeyError) as err:
        raise DatasetError(f"{path}: unreadable or corrupt dataset file ({err})") from err
    try:
        meta = json.loads(str(meta_raw[()]))
        if not isinstance(meta, dict):
            raise TypeError("metadata is not an object")
    except (TypeError, ValueError, IndexError) as err:
        raise DatasetError(f"{path}: bad metadata ({err})") from err
    _check(arrays, meta, str(path))
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
    if problems:
        raise DatasetError(f"{where}: " + "; ".join(problems))
