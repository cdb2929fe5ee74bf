"""Normalisation, windowing and hold-out of babbling data for the forward models and the CCGAN.

The training-data interface is plain arrays: pressure programs `[N, T, 3]` (bar) and the poses they
produced `[N, T, 6]` (tip position in m, then the unit d3 director), one pair per domain. The two
domains are unpaired: trajectory i of D_s has nothing to do with trajectory i of D_c, so each domain
is windowed and shuffled on its own.

Normalisation, the one rule: pressures are divided by `P_MAX_BAR` (3.5 bar, the valve's top);
poses go through `mjx_arm.dataset.normalise_pose` / `denormalise_pose`, which map each axis
linearly from the bounds [low, high] to [0, 1]: (pose - low) / (high - low). The only choice left
is the bounds (`PoseBounds`), and they span the workspace of both domains: bounds read from
dataset files (`read_domain`) are the files' exact `mjx_arm.dataset.workspace_bounds`; bounds ccgan
computes itself (`pose_bounds`, the default of `prepare`) are those workspace bounds widened by a
5% margin of each axis' span on either side, so held-out poses a little outside the training
data still land inside [0, 1]. Translators store the bounds they were trained with.

On disk the arrays come from `mjx_arm.babble`'s dataset files; `read_domain` and
`read_translation_files` load them through `mjx_arm.dataset.load_dataset` and refuse files that
do not belong together (another domain, another arm, other program lengths or units).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from mjx_arm import dataset
from mjx_arm.constants import CONTROL_HZ, N_CHAMBERS, P_MAX_BAR, POSE_DIM
from mjx_arm.dataset import workspace_bounds

#: Width of a pressure sample (one command per chamber); normalised pressure =
#: pressure_bar / `P_MAX_BAR` (`mjx_arm.constants`).
PRESSURE_DIM = N_CHAMBERS
#: A sample: normalised pressures (3) then normalised pose (6).
SAMPLE_DIM = PRESSURE_DIM + POSE_DIM


class PoseBounds(NamedTuple):
    """Per-axis pose bounds used to map poses to [0, 1].

    Attributes:
      low: [6] lower bounds (m for position, unitless for d3).
      high: [6] upper bounds; `high > low` on every axis.
    """

    low: np.ndarray
    high: np.ndarray

    def to_dict(self) -> dict:
        return {"low": np.asarray(self.low).tolist(), "high": np.asarray(self.high).tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> PoseBounds:
        return cls(np.asarray(d["low"], np.float64), np.asarray(d["high"], np.float64))


def union_bounds(*bounds: PoseBounds) -> PoseBounds:
    """The smallest bounds containing every given one ([6] each, dtype kept)."""
    return PoseBounds(
        np.minimum.reduce([np.asarray(b.low) for b in bounds]),
        np.maximum.reduce([np.asarray(b.high) for b in bounds]),
    )


def pose_bounds(*poses: np.ndarray, margin: float = 0.05, min_span: float = 1e-3) -> PoseBounds:
    """`mjx_arm.dataset.workspace_bounds` of every pose given (both domains), widened by `margin`.

    Args:
      *poses: arrays [..., 6] (m, unitless).
      margin: fraction of each axis' span added below and above.
      min_span: smallest span per axis (keeps a flat axis from dividing by ~0).

    Returns:
      `PoseBounds` with [6] float64 arrays.
    """
    low, high = (np.asarray(b, np.float64) for b in workspace_bounds(*poses))
    span = np.maximum(high - low, min_span)
    mid = 0.5 * (low + high)
    half = 0.5 * span * (1.0 + 2.0 * margin)
    return PoseBounds(mid - half, mid + half)


def normalise_pressure(pressure_bar):
    """[..., 3] bar -> [..., 3] in [0, 1] (pressure / P_MAX_BAR)."""
    return pressure_bar / P_MAX_BAR


def denormalise_pressure(pressure_norm):
    """[..., 3] normalised -> [..., 3] bar."""
    return pressure_norm * P_MAX_BAR


def normalise_pose(pose, bounds: PoseBounds) -> np.ndarray:
    """[..., 6] (m, unitless) -> [..., 6] float32 in [0, 1] inside the bounds (module docstring)."""
    return dataset.normalise_pose(pose, bounds.low, bounds.high)


def denormalise_pose(pose_norm, bounds: PoseBounds) -> np.ndarray:
    """[..., 6] normalised -> [..., 6] float32 (m, unitless); inverse of `normalise_pose`."""
    return dataset.denormalise_pose(pose_norm, bounds.low, bounds.high)


def check_domain_arrays(pressures_bar, poses, name: str = "data") -> tuple[np.ndarray, np.ndarray]:
    """Validates one domain's arrays; returns them as float32 `[N, T, 3]`, `[N, T, 6]`."""
    p = np.asarray(pressures_bar, np.float32)
    x = np.asarray(poses, np.float32)
    if p.ndim != 3 or p.shape[-1] != PRESSURE_DIM:
        raise ValueError(f"{name}: pressures must be [N, T, 3], got {p.shape}")
    if x.shape != p.shape[:2] + (POSE_DIM,):
        raise ValueError(f"{name}: poses must be [N, T, 6] matching pressures, got {x.shape}")
    if not (np.isfinite(p).all() and np.isfinite(x).all()):
        raise ValueError(f"{name}: non-finite values")
    return p, x


def samples(pressures_bar, poses, bounds: PoseBounds) -> np.ndarray:
    """Normalised samples `[..., 9]`: pressure / 3.5 (3) then pose in [0, 1] (6)."""
    return np.concatenate(
        [normalise_pressure(pressures_bar), normalise_pose(poses, bounds)], -1
    ).astype(np.float32)


def previous_poses(poses_norm: np.ndarray, rest_pose_norm: np.ndarray | None = None) -> np.ndarray:
    """The pose before each command: `[N, T, 6]` -> `[N, T, 6]`, shifted by one step.

    Step 0 gets `rest_pose_norm` [6] (the arm starts at rest) or, when None, the trajectory's own
    first pose.
    """
    first = (
        poses_norm[:, :1]
        if rest_pose_norm is None
        else np.broadcast_to(np.asarray(rest_pose_norm, poses_norm.dtype), poses_norm[:, :1].shape)
    )
    return np.concatenate([first, poses_norm[:, :-1]], 1)


def windows(x: np.ndarray, length: int, stride: int | None = None) -> np.ndarray:
    """Cuts aligned windows from every trajectory.

    Args:
      x: [N, T, D] trajectories.
      length: window length L (control steps), 1 <= L <= T.
      stride: step between window starts (default L, i.e. non-overlapping).

    Returns:
      [N * W, L, D] windows, W = (T - L) // stride + 1, trajectory-major.
    """
    n, t, d = x.shape
    stride = length if stride is None else stride
    if not 1 <= length <= t:
        raise ValueError(f"window length {length} must be in [1, T={t}]")
    starts = np.arange(0, t - length + 1, stride)
    idx = starts[:, None] + np.arange(length)[None]
    return x[:, idx].reshape(n * len(starts), length, d)


class DomainSplit(NamedTuple):
    """One domain, normalised, split into training windows and held-out trajectories.

    Attributes:
      train: [M, L, 9] training windows (pressure 3, pose 6; normalised).
      train_prev_pose: [M, L, 6] the normalised pose before each step of `train`.
      val: [V, T, 9] held-out whole trajectories.
      val_prev_pose: [V, T, 6].
    """

    train: np.ndarray
    train_prev_pose: np.ndarray
    val: np.ndarray
    val_prev_pose: np.ndarray


def split_domain(
    pressures_bar,
    poses,
    bounds: PoseBounds,
    window_length: int,
    n_val: int,
    stride: int | None = None,
    rest_pose=None,
    name: str = "data",
) -> DomainSplit:
    """Normalises one domain, holds out its last `n_val` trajectories, windows the rest.

    Args:
      pressures_bar: [N, T, 3] commands (bar).
      poses: [N, T, 6] poses (m, unitless).
      bounds: pose bounds shared by both domains.
      window_length: L, control steps per training window.
      n_val: trajectories held out (N - n_val >= 1).
      stride: window stride (default L).
      rest_pose: [6] pose at rest (m, unitless) or None (use each trajectory's first pose).

    Returns:
      `DomainSplit`.
    """
    p, x = check_domain_arrays(pressures_bar, poses, name)
    n = p.shape[0]
    if not 0 <= n_val < n:
        raise ValueError(f"{name}: n_val={n_val} must leave at least one of {n} trajectories")
    s = samples(p, x, bounds)
    rest = None if rest_pose is None else normalise_pose(np.asarray(rest_pose), bounds)
    prev = previous_poses(s[..., PRESSURE_DIM:], rest).astype(np.float32)
    tr, va = slice(0, n - n_val), slice(n - n_val, n)
    return DomainSplit(
        train=windows(s[tr], window_length, stride),
        train_prev_pose=windows(prev[tr], window_length, stride),
        val=s[va],
        val_prev_pose=prev[va],
    )


class TranslationData(NamedTuple):
    """Both domains, ready for `ccgan.train.make_train`.

    Attributes:
      source: D_s split.
      constrained: D_c split.
      bounds: the shared pose bounds.
    """

    source: DomainSplit
    constrained: DomainSplit
    bounds: PoseBounds


def prepare(
    pressures_s,
    poses_s,
    pressures_c,
    poses_c,
    window_length: int,
    n_val: int,
    stride: int | None = None,
    bounds: PoseBounds | None = None,
    rest_pose_s=None,
    rest_pose_c=None,
) -> TranslationData:
    """Normalises, holds out and windows both (unpaired) domains.

    Args:
      pressures_s, poses_s: D_s arrays [N_s, T_s, 3] (bar) and [N_s, T_s, 6].
      pressures_c, poses_c: D_c arrays [N_c, T_c, 3] and [N_c, T_c, 6]; N_c, T_c may differ.
      window_length: L (control steps).
      n_val: trajectories held out per domain.
      stride: window stride (default L).
      bounds: pose bounds; default spans the poses of both domains (`pose_bounds`).
      rest_pose_s, rest_pose_c: [6] rest poses or None.

    Returns:
      `TranslationData`.
    """
    if bounds is None:
        bounds = pose_bounds(poses_s, poses_c)
    kw = dict(window_length=window_length, n_val=n_val, stride=stride)
    return TranslationData(
        source=split_domain(pressures_s, poses_s, bounds, rest_pose=rest_pose_s, name="D_s", **kw),
        constrained=split_domain(
            pressures_c, poses_c, bounds, rest_pose=rest_pose_c, name="D_c", **kw
        ),
        bounds=bounds,
    )


def simulate(arm, pressures_bar: np.ndarray) -> np.ndarray:
    """Poses [N, T, 6] of programs [N, T, 3] (bar) on an `mjx_arm.Arm`, with MuJoCo C."""
    return np.asarray(arm.rollout(pressures_bar, backend="c"), np.float32)


# ---------------------------------------------------------------------------------- dataset files

#: The two data slots of a translation and the domains each accepts: D_s must be "source"; D_c
#: any other domain ("constrained", "aged", a custom one).
SLOTS = ("source", "constrained")


class DomainData(NamedTuple):
    """One slot's babbling files, checked to belong together and concatenated in order.

    Attributes:
      pressures_bar: [N, T, 3] float32 commands (bar) at 10 Hz, every file's trajectories.
      poses: [N, T, 6] float32 tip position (m) then unit d3.
      bounds: pose bounds spanning every file's stored ones ([6] float32 each).
      domain: the files' domain name.
      model_hash: `mjx_arm.Arm.model_hash` of the arm they were simulated with.
      paths: the files, as given.
      splits: each file's (split, trajectories), in order ("train", "val", ...).
    """

    pressures_bar: np.ndarray
    poses: np.ndarray
    bounds: PoseBounds
    domain: str
    model_hash: str
    paths: tuple[str, ...]
    splits: tuple[tuple[str, int], ...] = ()


def _listing(paths, values) -> str:
    return ", ".join(f"{p} ({v})" for p, v in zip(paths, values, strict=True))


def read_domain(
    paths: Sequence[str | os.PathLike], slot: str | None = None, model_hash: str | None = None
) -> DomainData:
    """Loads one domain's babbling files with `mjx_arm.dataset.load_dataset` and checks them.

    Files of one slot are concatenated (train first, then val: the last `n_val` trajectories
    are held out), so they must come from one domain, one arm and one program length, at the
    control rate and pressure scale this package assumes (10 Hz, pressures / 3.5 bar).

    Args:
      paths: .npz files written by `mjx_arm.babble` (`mjx_arm.dataset.save_dataset`).
      slot: "source": every file must hold domain "source"; "constrained": any other domain;
        None: either (the files must still agree with each other).
      model_hash: `Arm.model_hash` of the arm the data must come from, or None.

    Returns:
      `DomainData`.

    Raises:
      mjx_arm.dataset.DatasetError: naming the files: a missing, truncated or corrupt file; a
        domain wrong for the slot; files that mix domains, arms (model hashes: another MJCF,
        e.g. another segment count) or program lengths; another control rate or pressure
        scale. `ModelHashMismatchError` (a DatasetError) when a file's model hash is not
        `model_hash`; its message names both hashes.
    """
    from mjx_arm.dataset import DatasetError, load_dataset

    if slot not in (None, *SLOTS):
        raise ValueError(f"slot must be one of {SLOTS} or None, got {slot!r}")
    names = tuple(str(p) for p in paths)
    if not names:
        raise DatasetError(f"no {slot or 'dataset'} files given")
    sets = [load_dataset(p, expected_model_hash=model_hash) for p in paths]
    domains = [d.domain for d in sets]
    if slot == "source" and any(d != "source" for d in domains):
        raise DatasetError(
            "the source slot (--source) takes domain 'source' data only:"
            f" {_listing(names, domains)}"
        )
    if slot == "constrained" and "source" in domains:
        raise DatasetError(
            "the constrained slot (--constrained) takes data of a non-source domain"
            f" (constrained, aged, ...), not 'source': {_listing(names, domains)}"
        )
    for attr, what in (
        ("domain", "domains"),
        ("model_hash", "arms (model hashes differ: another MJCF, e.g. another segment count)"),
        ("n_steps", "program lengths (control steps)"),
    ):
        values = [getattr(d, attr) for d in sets]
        if len(set(values)) > 1:
            raise DatasetError(f"{slot or 'the'} files mix {what}: {_listing(names, values)}")
    for attr, want, what in (
        ("control_hz", CONTROL_HZ, "control rate (Hz)"),
        ("pressure_scale_bar", P_MAX_BAR, "pressure scale (bar)"),
    ):
        values = [getattr(d, attr) for d in sets]
        if any(v != want for v in values):
            raise DatasetError(f"need a {what} of {want}: {_listing(names, values)}")
    return DomainData(
        pressures_bar=np.concatenate([d.pressures_bar for d in sets]),
        poses=np.concatenate([d.poses for d in sets]),
        bounds=union_bounds(*(PoseBounds(d.pose_low, d.pose_high) for d in sets)),
        domain=sets[0].domain,
        model_hash=sets[0].model_hash,
        paths=names,
        splits=tuple((d.split, int(d.pressures_bar.shape[0])) for d in sets),
    )


def check_slot_splits(n_val: int, d_s: DomainData, d_c: DomainData) -> list[str]:
    """`check_splits` of both slots (--source, --constrained); returns their notes."""
    notes = [
        check_splits(d, n_val, flag) for flag, d in (("--source", d_s), ("--constrained", d_c))
    ]
    return [note for note in notes if note]


def check_splits(d: DomainData, n_val: int, flag: str = "the files") -> str | None:
    """Refuses a slot's files whose splits do not fit how training uses them.

    Training concatenates the files in order and holds out the last `n_val` trajectories
    (`prepare`). So a file of the "val" split must come after every "train" file and must not
    be the only data (it would be trained on), and when "val" files are given the held-out
    trajectories must all come from them (else a "train" file is held out as validation data).
    Without any "val" file the last `n_val` trajectories of the "train" files are held out.

    Args:
      d: one slot's files (`read_domain`).
      n_val: trajectories held out (TrainConfig.n_val).
      flag: the option that named the files, for messages.

    Returns:
      None, or a note when the "val" files hold more than `n_val` trajectories: the rest of
      them are trained on (the chain's ccgan_large holds out 3 of its 10).

    Raises:
      mjx_arm.dataset.DatasetError: naming the files and their splits; or, first, as
        `check_identities`.
    """
    from mjx_arm.dataset import DatasetError

    check_identities(d, n_val, flag)
    listing = _listing(d.paths, [split for split, _ in d.splits])
    kinds = [split for split, _ in d.splits]
    if "train" not in kinds and "val" in kinds:
        raise DatasetError(
            f"{flag}: only validation-split files, which training would train on: {listing};"
            " give the training-split file first (<domain>_train.npz, then <domain>_val.npz)"
        )
    last_train = max((i for i, k in enumerate(kinds) if k == "train"), default=-1)
    if any(k == "val" for k in kinds[: last_train + 1]):
        raise DatasetError(
            f"{flag}: a validation-split file comes before a training-split one, so training"
            f" would train on it and hold out training data: {listing}; list the"
            " validation file last"
        )
    n_val_files = sum(n for split, n in d.splits if split == "val")
    if 0 < n_val_files < n_val:
        raise DatasetError(
            f"{flag}: --n-val {n_val} holds out {n_val - n_val_files} trajectories of the"
            f" training-split files besides the {n_val_files} of the validation-split ones:"
            f" {listing}; give --n-val {n_val_files}"
        )
    if n_val_files > n_val:
        return (
            f"{flag}: --n-val {n_val} holds out {n_val} of the {n_val_files} validation-split"
            f" trajectories; the other {n_val_files - n_val} are trained on (--n-val"
            f" {n_val_files} holds out the whole validation file)"
        )
    return None


def array_digest(*arrays: np.ndarray) -> str:
    """sha256 (hex) of the arrays' shapes, dtypes and bytes, in order: equal for equal data,
    whatever the file's name, split or other metadata."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def check_identities(d: DomainData, n_val: int, flag: str = "the files") -> None:
    """Refuses a slot whose held-out trajectories are also trained on, judged by content.

    Names and splits do not show a file listed twice, a training file copied as a validation
    file, or one trajectory saved in both: each would hold out a trajectory that training has
    seen, and the held-out error would measure memory. So two files with the same arrays
    (`array_digest` of pressures and poses) are refused, and so is any of the last `n_val`
    trajectories (held out by `prepare`) whose arrays equal those of a trained one.

    Args:
      d: one slot's files (`read_domain`; `d.splits` gives each file's trajectories).
      n_val: trajectories held out (TrainConfig.n_val).
      flag: the option that named the files, for messages.

    Raises:
      mjx_arm.dataset.DatasetError: one line naming both files (or trajectories) and the digest.
    """
    from mjx_arm.dataset import DatasetError

    starts = np.cumsum([0, *(n for _, n in d.splits)])
    seen: dict[str, str] = {}
    for path, a, b in zip(d.paths if d.splits else (), starts[:-1], starts[1:], strict=True):
        digest = array_digest(d.pressures_bar[a:b], d.poses[a:b])
        if digest in seen:
            raise DatasetError(
                f"{flag}: {seen[digest]} and {path} hold the same data (sha256 {digest[:12]}),"
                " so held-out trajectories would be trained on; list each file once"
            )
        seen[digest] = path
    n_train = max(d.pressures_bar.shape[0] - n_val, 0)
    check_unseen(d, n_val, d, flag, trained_rows=n_train)


def _trajectory_name(d: DomainData, i: int) -> str:
    """`path[row]` of trajectory i of the concatenated files (or `trajectory i`)."""
    if not d.splits:
        return f"trajectory {i}"
    starts = np.cumsum([0, *(n for _, n in d.splits)])
    f = int(np.searchsorted(starts, i, side="right")) - 1
    return f"{d.paths[f]}[{i - starts[f]}]"


def check_unseen(
    held: DomainData,
    n_val: int,
    trained: DomainData,
    flag: str = "the files",
    trained_rows: int | None = None,
) -> None:
    """Refuses when one of `held`'s last `n_val` trajectories (held out by `prepare`) has the
    same arrays (`array_digest` of pressures and poses) as one of `trained`'s first
    `trained_rows` (default: all of them), e.g. --forward-data that F_c trains on.

    Raises:
      mjx_arm.dataset.DatasetError: one line naming both trajectories (`path[row]`).
    """
    from mjx_arm.dataset import DatasetError

    n_trained = trained.pressures_bar.shape[0] if trained_rows is None else trained_rows
    seen = {array_digest(trained.pressures_bar[j], trained.poses[j]): j for j in range(n_trained)}
    n = held.pressures_bar.shape[0]
    for i in range(max(n - n_val, 0), n):
        j = seen.get(array_digest(held.pressures_bar[i], held.poses[i]))
        if j is not None:
            raise DatasetError(
                f"{flag}: held-out trajectory {_trajectory_name(held, i)} is also trained on:"
                f" {_trajectory_name(trained, j)} holds the same arrays; hold out trajectories"
                " that training does not see"
            )


def read_translation_files(
    source: Sequence[str | os.PathLike],
    constrained: Sequence[str | os.PathLike],
    model_hash: str | None = None,
) -> tuple[DomainData, DomainData]:
    """Both slots' files (`read_domain` each), which must come from one arm.

    The two domains put the same MJCF in different media, so their model hashes agree; files of
    two different arms would train a translator between the wrong worlds.

    Raises:
      mjx_arm.dataset.DatasetError: as `read_domain`, or the slots' model hashes differ.
    """
    from mjx_arm.dataset import DatasetError

    d_s = read_domain(source, "source", model_hash)
    d_c = read_domain(constrained, "constrained", model_hash)
    if d_s.model_hash != d_c.model_hash:
        raise DatasetError(
            "source and constrained files come from different arms (model hashes differ:"
            f" another MJCF, e.g. another segment count): {', '.join(d_s.paths)}"
            f" ({d_s.model_hash}) vs {', '.join(d_c.paths)} ({d_c.model_hash})"
        )
    return d_s, d_c
