"""The forward-model stage of `ccgan.train`: the windows F_s and F_c train on, and their files.

`python -m ccgan.train` trains F_s and F_c before the CCGAN (`train_forward_models`), or copies
them from another workdir (`copy_forward_models`, --forward-from). `forward_meta` ties them to
their settings and data, so a workdir's models are reused only for the run they fit.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan.config import TrainConfig
from ccgan.data import TranslationData
from ccgan.forward import ForwardConfig
from ccgan.run_files import data_fingerprint
from mjx_arm.atomic import write_atomically

#: The files of the forward stage in a workdir.
FORWARD_FILES = ("forward_s.ckpt", "forward_c.ckpt", "forward_metrics.json")


def forward_splits(
    data: TranslationData, d_s, d_c, config: TrainConfig, window: int, forward_c=None
) -> dict:
    """The windows F_s and F_c train on: {"forward_s": DomainSplit, "forward_c": DomainSplit}.

    By default both are the CCGAN's own windows (`data`). `window` (control steps) re-cuts the
    programs (`d_s`, `d_c`: `ccgan.data.DomainData`) to another length: open-loop training
    (`ForwardConfig.open_loop`) wants windows as long as the horizon F_c predicts in the feedback
    loss (window_length x k). `forward_c`, D_c babbling of the same arm (a `DomainData`, e.g.
    with holds long enough for the slow D_c arm to settle:
    `studies/results/h200/issue29/forward_data/forward_data.md`), replaces D_c's training
    programs for F_c. Either way F_c is evaluated on the CCGAN's held-out D_c programs, and
    every window is normalised with the CCGAN's pose bounds.
    """
    if window == config.window_length and forward_c is None:
        return {"forward_s": data.source, "forward_c": data.constrained}

    def cut(d, n_val, name):
        return data_lib.split_domain(
            d.pressures_bar, d.poses, data.bounds, window, n_val, name=name
        )

    train_c = cut(d_c, config.n_val, "D_c") if forward_c is None else cut(forward_c, 0, "F_c data")
    return {
        "forward_s": cut(d_s, config.n_val, "D_s"),
        "forward_c": data.constrained._replace(
            train=train_c.train, train_prev_pose=train_c.train_prev_pose
        ),
    }


def forward_meta(fconf: ForwardConfig, data: TranslationData, splits: dict | None = None) -> dict:
    """The metadata that ties F_s and F_c to their settings and data (checked on resume and by
    --forward-from). Windows other than the CCGAN's own (`forward_splits`) add their hash."""
    meta = {"config": dataclasses.asdict(fconf), "data": data_fingerprint(data)}
    if splits is not None and (
        splits["forward_s"] is not data.source or splits["forward_c"] is not data.constrained
    ):
        meta["forward_windows"] = checkpoint.fingerprint(
            *(a for split in splits.values() for a in (split.train, split.train_prev_pose))
        )
    return meta


def train_forward_models(
    fconf: ForwardConfig,
    data: TranslationData,
    workdir: Path,
    progress=True,
    resume=False,
    splits: dict | None = None,
    f_meta: dict | None = None,
):
    """Trains F_s and F_c, writes `forward_{s,c}.ckpt` and `forward_metrics.json` to workdir.

    F_s is not used by the CCGAN; it is trained for the report, as in the paper. The bar
    advances per epoch (minutes per model on a CPU at the default 300 epochs). Each model's
    checkpoint and metrics are written as soon as it is trained, so with `resume` a run stopped
    during F_c (a time limit, `experiments.paper`'s deadline) keeps F_s: a model whose checkpoint
    was trained with these settings on this data, and whose metrics are in the file, is not
    trained again.
    """
    from tqdm.auto import tqdm

    from ccgan import forward as forward_lib

    splits = splits or {"forward_s": data.source, "forward_c": data.constrained}
    f_meta = f_meta or forward_meta(fconf, data, splits)
    metrics_path = workdir / "forward_metrics.json"
    report = _finished_forward_models(workdir, metrics_path, f_meta) if resume else {}
    models = [(name, split) for name, split in splits.items() if name not in report]
    bar = tqdm(
        total=len(models) * fconf.epochs, desc="forward models", unit="epoch", disable=not progress
    )
    for name in report:
        bar.write(f"{name}: trained already with these settings ({workdir / f'{name}.ckpt'})")
    for name, split in models:
        bar.set_postfix_str(name)
        params, hist, metrics = forward_lib.train_forward(
            fconf, split, data.bounds, on_epoch=lambda _: bar.update(1)
        )
        checkpoint.save(workdir / f"{name}.ckpt", params, f_meta)
        report[name] = metrics | {"final_loss": float(hist[-1])}
        write_atomically(metrics_path, lambda f: f.write(json.dumps(report, indent=2).encode()))
        bar.write(f"{name} {json.dumps(report[name])}")
    bar.close()
    return report


def _finished_forward_models(workdir: Path, metrics_path: Path, f_meta: dict) -> dict:
    """{name: metrics} of the forward models in workdir that a resumed run can keep."""
    try:
        stored = json.loads(metrics_path.read_text())
    except (OSError, ValueError):
        return {}
    done = {}
    for name in ("forward_s", "forward_c"):
        try:
            _, stored_meta = checkpoint.load(workdir / f"{name}.ckpt", expect=f_meta)
        except checkpoint.CheckpointError:  # absent, corrupt or made otherwise: trained again
            continue
        if stored_meta.get("forward_windows") != f_meta.get("forward_windows"):
            continue  # trained on other windows
        if isinstance(stored, dict) and name in stored:
            done[name] = stored[name]
    return done


def copy_forward_models(parser, source: Path, workdir: Path, f_meta: dict) -> None:
    """Copies F_s, F_c and their metrics from another workdir, after checking that they were
    trained on this data with these settings (a usage error otherwise, before any training)."""
    missing = [name for name in FORWARD_FILES if not (source / name).is_file()]
    if missing:
        parser.error(f"--forward-from {source}: no {', '.join(missing)} there")
    for name in ("forward_s.ckpt", "forward_c.ckpt"):
        try:
            _, stored = checkpoint.load(source / name, expect=f_meta)
        except checkpoint.CheckpointError as err:
            parser.error(f"--forward-from: {err}")
        if stored.get("forward_windows") != f_meta.get("forward_windows"):
            parser.error(
                f"--forward-from: {source / name} was trained on other windows (forward_windows"
                " differ): pass the --forward-data and --forward-window it was trained with"
            )
    for name in FORWARD_FILES:
        shutil.copy2(source / name, workdir / name)
