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


class CheckpointNotFoundError(CheckpointError, FileNotFoundError):
    """No file at the checkpoint's path (both a CheckpointError and a FileNotFoundError)."""


def _short(value: Any, limit: int = 60) -> str:
    """repr(value), cut to `limit` characters: a garbled file must not flood the message."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def differences(stored: Any, wanted: Any, prefix: str = "") -> list[str]:
    """The leaves where two JSON-like values differ, as "key: stored X, this run Y" lines.

    Nested dicts are compared key by key (`prefix` names the parent, dotted), so a changed
    config names the changed fields rather than printing both configs whole.
    """
    if isinstance(stored, dict) and isinstance(wanted, dict):
        out = []
        for key in sorted(set(stored) | set(wanted), key=str):
            name = f"{prefix}.{key}" if prefix else str(key)
            if key not in stored:
                out.append(f"{name}: not stored, this run {_short(wanted[key])}")
            elif key not in wanted:
                out.append(f"{name}: stored {_short(stored[key])}, not in this run")
            else:
                out += differences(stored[key], wanted[key], name)
        return out
    if stored == wanted:
        return []
    return [f"{prefix or 'value'}: stored {_short(stored)}, this run {_short(wanted)}"]


def fingerprint(*arrays) -> str:
    """Short sha256 of arrays (shape, dtype and bytes), to tie a checkpoint to its data."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(str((a.shape, a.dtype.str)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def _write_atomically(path: Path, blob: bytes) -> None:
    """Writes `blob` to a temporary file beside `path`, fsyncs it and renames it over `path`."""
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
    _write_atomically(path, blob)
    return path


def read(path: str | os.PathLike) -> tuple[dict, bytes]:
    """Reads and verifies a checkpoint; returns (meta, payload bytes).

    Raises:
      CheckpointNotFoundError: no file at `path` (a CheckpointError and a FileNotFoundError).
      CheckpointError: not a checkpoint, or payload hash mismatch. The message names the file
        and the kind of damage, never the file's bytes.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointNotFoundError(f"no checkpoint at {path}")
    try:
        rec = msgpack.unpackb(path.read_bytes(), raw=False)
        fmt, meta, digest, payload = rec["format"], rec["meta"], rec["sha256"], rec["payload"]
    except Exception as err:  # msgpack raises several types on truncated/garbled input
        # Only the exception's type: msgpack's messages (ExtraData) embed the undecoded bytes.
        raise CheckpointError(
            f"{path} is not a readable {FORMAT} checkpoint (truncated or not a checkpoint:"
            f" {type(err).__name__})"
        ) from None
    if fmt != FORMAT:
        raise CheckpointError(f"{path} has format {_short(fmt)}, expected {FORMAT!r}")
    if not isinstance(payload, bytes) or hashlib.sha256(payload).hexdigest() != digest:
        raise CheckpointError(f"{path} is corrupt: payload sha256 does not match its header")
    try:
        return json.loads(meta), payload
    except (TypeError, ValueError) as err:
        raise CheckpointError(f"{path} has unreadable metadata ({type(err).__name__})") from None


def payload_sha256(path: str | os.PathLike) -> str:
    """The sha256 (hex) of a checkpoint's payload, verified (`read`): it names the stored tree
    whatever the metadata says (a file whose metadata was rewritten keeps it).

    Raises:
      CheckpointNotFoundError, CheckpointError: as `read`.
    """
    _, payload = read(path)
    return hashlib.sha256(payload).hexdigest()


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
      CheckpointNotFoundError: no file at `path`.
      CheckpointError: corrupt file, mismatched metadata (the message names each differing
        field with its stored and expected value), or mismatched tree structure.
    """
    meta, payload = read(path)
    for key, want in (expect or {}).items():
        have = meta.get(key)
        want = json.loads(json.dumps(want, sort_keys=True))
        if want != have:
            diff = "; ".join(differences(have, want, key))
            raise CheckpointError(f"{path} does not match this run: {diff}")
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


#: The name `ccgan.load_translator` and `eval` read for a folder's first trained seed.
FIRST_SEED_NAME = "translator.ckpt"


def link_first_seed(folder: str | os.PathLike, seed_file: str) -> Path:
    """Makes `folder/translator.ckpt` name `seed_file` (a file in the same folder).

    A relative symbolic link, so the folder holds each trained model once and can be moved whole;
    where links are not allowed, a copy. Replaced atomically, so a reader never sees it missing.
    """
    folder = Path(folder)
    link = folder / FIRST_SEED_NAME
    tmp = folder / f".{FIRST_SEED_NAME}.{os.getpid()}.tmp"
    try:
        tmp.unlink(missing_ok=True)
        os.symlink(seed_file, tmp)
    except OSError:
        tmp.write_bytes((folder / seed_file).read_bytes())
    os.replace(tmp, link)
    return link


def rewrite_meta(path: str | os.PathLike, update: dict) -> dict:
    """Adds or replaces metadata keys of a checkpoint file, leaving its payload byte for byte.

    The file is read and verified (`read`), its meta updated with `update`, and written back
    atomically with the same payload bytes and payload sha256; the written file is read again
    and its payload digest compared with the old one.

    Args:
      path: a checkpoint file (not a symbolic link: a link's target is the file to rewrite).
      update: JSON-able metadata keys to set.

    Returns:
      {"payload_sha256": unchanged digest, "meta": the new metadata}.

    Raises:
      CheckpointError: as `read`, `path` is a symbolic link, or the payload digest changed.
    """
    path = Path(path)
    if path.is_symlink():
        raise CheckpointError(f"{path} is a symbolic link: rewrite the file it names")
    meta, payload = read(path)
    digest = hashlib.sha256(payload).hexdigest()
    new_meta = meta | json.loads(json.dumps(update, sort_keys=True))
    blob = msgpack.packb(
        {
            "format": FORMAT,
            "meta": json.dumps(new_meta, sort_keys=True),
            "sha256": digest,
            "payload": payload,
        },
        use_bin_type=True,
    )
    _write_atomically(path, blob)
    _, again = read(path)
    if hashlib.sha256(again).hexdigest() != digest:
        raise CheckpointError(f"{path}: payload digest changed while rewriting its metadata")
    return {"payload_sha256": digest, "meta": new_meta}
