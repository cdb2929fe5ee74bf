"""A trained G_c packaged for use: D_s pressure programs in, D_c pressure programs out."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ccgan import checkpoint
from ccgan.data import (
    PRESSURE_DIM,
    PoseBounds,
    denormalise_pose,
    denormalise_pressure,
    normalise_pose,
    samples,
)
from ccgan.models import ForwardModel, Generator, forward_open_loop

#: Where `load_translator()` looks when given no path (override with $CCGAN_TRANSLATOR).
DEFAULT_PATH = Path(__file__).resolve().parent.parent / "results" / "ccgan" / "translator.ckpt"


def save_translator(
    path,
    g_c_params,
    k: int,
    bounds: PoseBounds,
    config,
    forward_c_params=None,
    forward_model: ForwardModel | None = None,
) -> Path:
    """Writes G_c (and optionally F_c), k and the pose bounds to one checkpoint file."""
    fwd = forward_model or ForwardModel()
    tree = {"g_c": g_c_params}
    if forward_c_params is not None:
        tree["f_c"] = forward_c_params
    meta = {
        "kind": "translator",
        "k": int(k),
        "bounds": bounds.to_dict(),
        "generator": {"hidden": config.gen_hidden, "fc": config.gen_fc},
        "forward": {"hidden": fwd.hidden, "fc": fwd.fc},
        "config": config.to_dict(),
    }
    return checkpoint.save(path, tree, meta)


@dataclasses.dataclass
class Translator:
    """G_c with its time-stretching factor k and the normalisation it was trained with."""

    g_c_params: dict
    k: int
    bounds: PoseBounds
    generator: Generator
    f_c_params: dict | None = None
    forward_model: ForwardModel | None = None

    def translate(self, pressures_s, poses_s) -> tuple[np.ndarray, int]:
        """Translates a D_s program into D_c.

        Args:
          pressures_s: [T, 3] D_s commands (bar, 10 Hz).
          poses_s: [T, 6] the D_s poses they produce (tip position m, unit d3).

        Returns:
          (pressures_c [T * k, 3] bar: each translated command held k control periods, k).
        """
        p = np.asarray(pressures_s, np.float32)
        x = np.asarray(poses_s, np.float32)
        if p.ndim != 2 or p.shape[1] != 3 or x.shape != (p.shape[0], 6):
            raise ValueError(f"need pressures [T, 3] and poses [T, 6], got {p.shape}, {x.shape}")
        s = samples(p, x, self.bounds)[None]
        out = np.asarray(self.generator.apply(self.g_c_params, jnp.asarray(s)))[0]
        commands = denormalise_pressure(out[:, :PRESSURE_DIM]).astype(np.float64)
        return np.repeat(commands, self.k, axis=0), self.k

    def predict_poses(self, pressures_c, pose0) -> np.ndarray:
        """F_c's open-loop poses [T', 6] (m, unit d3) for D_c commands [T', 3] (bar) from pose0 [6].

        Raises:
          ValueError: the file held no F_c.
        """
        if self.f_c_params is None:
            raise ValueError("this translator was saved without F_c")
        p = jnp.asarray(np.asarray(pressures_c, np.float32) / 3.5)[None]
        x0 = jnp.asarray(normalise_pose(np.asarray(pose0, np.float32), self.bounds))[None]
        pred = forward_open_loop(self.forward_model, self.f_c_params, p, x0)
        return denormalise_pose(np.asarray(pred[0], np.float64), self.bounds)


def translator_path(path: str | os.PathLike | None = None) -> Path:
    """The file `load_translator(path)` reads: path, else $CCGAN_TRANSLATOR, else DEFAULT_PATH."""
    return Path(path or os.environ.get("CCGAN_TRANSLATOR", DEFAULT_PATH))


def load_translator(path: str | os.PathLike | None = None) -> Translator:
    """Loads a translator written by `ccgan.train` (default: $CCGAN_TRANSLATOR or DEFAULT_PATH).

    Raises:
      ccgan.checkpoint.CheckpointError: missing, corrupt, or not a translator file.
    """
    path = translator_path(path)
    return translator_from_checkpoint(checkpoint.load(path), path)


def translator_from_checkpoint(source: tuple[dict, dict], path="checkpoint") -> Translator:
    """The translator of a loaded translator file (`checkpoint.load`'s (tree, meta) pair).

    Raises:
      ccgan.checkpoint.CheckpointError: not a translator file (`path` names it in the message).
    """
    tree, meta = source
    if meta.get("kind") != "translator":
        raise checkpoint.CheckpointError(f"{path} is not a translator checkpoint")
    fwd = ForwardModel(**meta["forward"])
    return Translator(
        g_c_params=tree["g_c"],
        k=int(meta["k"]),
        bounds=PoseBounds.from_dict(meta["bounds"]),
        generator=Generator(**meta["generator"]),
        f_c_params=tree.get("f_c"),
        forward_model=fwd,
    )
