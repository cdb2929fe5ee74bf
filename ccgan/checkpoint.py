"""Atomic, self-checking checkpoints of pytrees (flax.serialization msgpack).

A checkpoint file is a msgpack map {"format", "meta", "sha256", "payload"}: `payload` holds the
pytree's state dict as msgpack bytes, `sha256` its digest, `meta` a JSON string (config, epoch,
data fingerprint, ...). It is written to a temporary file in the same folder, fsynced, then renamed
over the target with `os.replace`, so a crash leaves either the old or the new file, never half of
one. Loading re-hashes the payload and compares the metadata the caller expects, and raises
`CheckpointError` naming what is wrong.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
from flax import serialization

FORMAT = "ccgan-ckpt-v1"


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt, or does not match what the caller expects."""


def fingerprint(*arrays) -> str:
    """Short sha256 of arrays (shape, dtype and bytes), to tie a checkpoint to its data."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(str((a.shape, a.dtype.str)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def save(path: str | os.PathLike, tree: Any, meta: dict) -> Path:
    """Writes `tree` and JSON-able `meta` to `path` atomically.

    Args:
      path: target file.
      tree: a pytree of arrays (params, optimiser state, train state, ...).
      meta: JSON-serialisable metadata.

    Returns:
      The path written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = serialization.to_bytes(tree)
    blob = msgpack.packb(
        {
            "format": FORMAT,
            "meta": json.dumps(meta, sort_keys=True),
            "sha256": hashlib.sha256(payload).hexdigest(),
            "payload": payload,
        },
        use_bin_type=True,
    )
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(blob)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def read(path: str | os.PathLike) -> tuple[dict, bytes]:
    """Reads and verifies a checkpoint; returns (meta, payload bytes).

    Raises:
      CheckpointError: missing file, not a checkpoint, or payload hash mismatch.
    """
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f"no checkpoint at {path}")
    try:
        rec = msgpack.unpackb(path.read_bytes(), raw=False)
        fmt, meta, digest, payload = rec["format"], rec["meta"], rec["sha256"], rec["payload"]
    except Exception as err:  # msgpack raises several types on truncated/garbled input
        raise CheckpointError(f"{path} is not a readable checkpoint ({err!r})") from err
    if fmt != FORMAT:
        raise CheckpointError(f"{path} has format {fmt!r}, expected {FORMAT!r}")
    if hashlib.sha256(payload).hexdigest() != digest:
        raise CheckpointError(f"{path} is corrupt: payload sha256 does not match its header")
    return json.loads(meta), payload


def load(
    path: str | os.PathLike, target: Any = None, expect: dict | None = None
) -> tuple[Any, dict]:
    """Loads a checkpoint.

    Args:
      path: the file.
      target: a pytree with the expected structure (restored into it), or None for a raw
        nested dict of arrays.
      expect: metadata keys whose values must equal the stored ones (e.g. config, data hash).

    Returns:
      (tree, meta).

    Raises:
      CheckpointError: corrupt file, mismatched metadata, or mismatched tree structure.
    """
    meta, payload = read(path)
    for key, want in (expect or {}).items():
        have = meta.get(key)
        if json.loads(json.dumps(want, sort_keys=True)) != have:
            raise CheckpointError(
                f"{path} does not match this run: meta[{key!r}] is {have!r}, expected {want!r}"
            )
    try:
        state = serialization.msgpack_restore(payload)
        tree = state if target is None else serialization.from_state_dict(target, state)
    except Exception as err:
        raise CheckpointError(f"{path}: stored tree does not fit the expected one ({err})") from err
    if target is not None:
        import jax

        want_shapes = [np.shape(x) for x in jax.tree.leaves(target)]
        have_shapes = [np.shape(x) for x in jax.tree.leaves(tree)]
        if want_shapes != have_shapes:
            raise CheckpointError(f"{path}: array shapes differ from the expected tree")
    return tree, meta
