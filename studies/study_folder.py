"""The babbling and forward models of a `tools/device/ccgan_study.sh` folder, read once for a study.

A study folder holds `babble/` (the paper-scale babbling of both domains, `mjx_arm.babble`) and
`forward/` (F_s and F_c, `ccgan.train --forward-only`). The studies that build on it
(`studies.forward_open_loop`, `studies.forward_data`, `studies.ccgan_ablation`,
`studies.ccgan_budget`) all need the same things from it: both arms, both domains' data, the
shared pose bounds the GAN normalises with, and the held-out D_s programs.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

import mjx_arm
from ccgan import data as data_lib
from mjx_arm.dataset import load_dataset


class StudyFolder(NamedTuple):
    """What a study reads from a study folder.

    Attributes:
      folder: the folder.
      arm_s, arm_c: the arm in D_s and in D_c (`mjx_arm.Arm`).
      d_s, d_c: both domains' babbling, train then val (`ccgan.data.DomainData`).
      bounds: the pose bounds spanning both domains (what `ccgan.train` normalises with).
      n_val: held-out programs per domain (the last n_val of d_s and of d_c).
    """

    folder: Path
    arm_s: object
    arm_c: object
    d_s: data_lib.DomainData
    d_c: data_lib.DomainData
    bounds: data_lib.PoseBounds
    n_val: int

    @property
    def heldout_programs_bar(self) -> np.ndarray:
        """[n_val, T, 3] float64: the held-out D_s programs (bar), never trained on."""
        return np.asarray(self.d_s.pressures_bar[-self.n_val :], np.float64)

    @property
    def heldout_poses_s(self) -> np.ndarray:
        """[n_val, T, 6] float64: their poses in D_s (the paths a translation must trace)."""
        return np.asarray(self.d_s.poses[-self.n_val :], np.float64)

    def translation_data(self, window_length: int, n_val: int) -> data_lib.TranslationData:
        """Both domains prepared for CCGAN training with windows of `window_length`."""
        return data_lib.prepare(
            self.d_s.pressures_bar, self.d_s.poses, self.d_c.pressures_bar, self.d_c.poses,
            window_length, n_val, None, bounds=self.bounds,
        )  # fmt: skip


def load_study_folder(folder: str | Path, model: str | Path = "models/softarm.xml") -> StudyFolder:
    """Reads `folder`/babble (checked against `model`'s hash) and loads both arms.

    Raises:
      mjx_arm.dataset.DatasetError: files missing, corrupt, or of another arm.
    """
    folder = Path(folder)
    arm_s = mjx_arm.load(model, domain="source")
    arm_c = mjx_arm.load(model, domain="constrained")
    babble = folder / "babble"
    d_s, d_c = data_lib.read_translation_files(
        [babble / f"source_{s}.npz" for s in ("train", "val")],
        [babble / f"constrained_{s}.npz" for s in ("train", "val")],
        arm_c.model_hash,
    )
    n_val = len(load_dataset(babble / "source_val.npz").pressures_bar)
    bounds = data_lib.union_bounds(d_s.bounds, d_c.bounds)
    return StudyFolder(folder, arm_s, arm_c, d_s, d_c, bounds, n_val)
