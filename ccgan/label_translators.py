"""One-off: labels the previous I-Support arm's translators with what they are, payloads untouched.

Translator files written before `ccgan.translator.LABELS` existed record their model hash but not
their method or domains, so the aged pair's CCGAN-GP could be scored on D_c and a WCGAN-GP file
as CCGAN-GP. This adds the labels to the chain's first run (`results/paper/run/<stage>/
translator_seed*.ckpt`; `translator.ckpt` links to seed 0's) with `checkpoint.rewrite_meta`,
which keeps each payload byte for byte and checks its sha256 afterwards.

Each label is read from what made the file, never assumed: the method from the training config's
`baseline` or the fine-tune stage's record, the target domain from the stage's command in its
`stage.json` (the `--constrained` data file's domain, or `--domain`), the model hash from the
file, which must be the arm of `models/softarm_linear.xml` (the I-Support arm that run was made
on, kept byte for byte when `models/softarm.xml` moved on). What changed goes to
`results/paper/run/translator_labels.json`: each file's labels, its payload sha256 and its file
sha256 before and after (the stage manifests keep the digests the stages wrote).

    python -m ccgan.label_translators            # label (a labelled file is left as it is)
    python -m ccgan.label_translators --check    # only say whether every file is labelled
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from ccgan import checkpoint
from ccgan.cli import cli_parser
from ccgan.translator import LABELS, LINEAR_TRANSLATORS_DIR, missing_labels
from mjx_arm import constants

#: The run folder labelled: the chain's first run, of the previous arm (the chain's rerun on
#: models/softarm.xml wrote labelled files).
RUN_DIR = LINEAR_TRANSLATORS_DIR
#: The arm that run was made with (models/softarm.xml when the chain ran, since kept as
#: models/softarm_linear.xml).
RUN_MODEL = constants.LINEAR_LAW_MODEL_PATH
#: The run's stage folders that hold translators.
STAGES = ("ccgan", "wcgan", "ccgan_large", "aged", "ccgan_sim", "aged_sim")
#: The record of what was relabelled, beside the stage folders.
RECORD = "translator_labels.json"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def stage_target_domain(stage_json: dict) -> str:
    """The domain a stage's translators translate into, from its recorded command: a distill or
    finetune stage's `--domain`, a training's `--constrained` data file (`<domain>_<split>.npz`).

    Raises:
      ValueError: the command names neither.
    """
    args = stage_json["key"]["args"]
    if "--domain" in args:
        return args[args.index("--domain") + 1]
    if "--constrained" in args:
        return Path(args[args.index("--constrained") + 1]).name.split("_")[0]
    raise ValueError(f"stage {stage_json.get('stage')}: its command names no D_c domain")


def file_method(meta: dict) -> str:
    """ "ccgan", "wcgan", "distill" or "finetune", from what the file records of its making."""
    if meta.get("finetune"):
        return meta["finetune"].get("method", "finetune")
    return "wcgan" if meta["config"]["baseline"] else "ccgan"


def labels_of(path: Path, meta: dict, stage_json: dict, model_hash: str) -> dict:
    """The `LABELS` of one translator file of a stage.

    Raises:
      ValueError: the file's recorded arm is not `model_hash`, or its fine-tune record names
        another domain than the stage's command.
    """
    target = stage_target_domain(stage_json)
    recorded = (meta.get("finetune") or {}).get("model_hash") or meta.get("model_hash")
    if recorded != model_hash:
        raise ValueError(f"{path} records arm {recorded}, not {RUN_MODEL.name}'s {model_hash}")
    stage_domain = (meta.get("finetune") or {}).get("domain", target)
    if stage_domain != target:
        raise ValueError(f"{path} records domain {stage_domain}, its stage's command {target}")
    return {
        "method": file_method(meta),
        "source_domain": "source",
        "target_domain": target,
        "model_hash": model_hash,
    }


def label_run(run: Path = RUN_DIR, check: bool = False, log=print) -> dict:
    """Labels every translator file of the run folder `run` (see the module docstring).

    Returns:
      {file relative to run: {"labels", "payload_sha256", "file_sha256_before",
      "file_sha256_after"}} of the files labelled now (with `check`: those that would be).
    """
    import mjx_arm

    model_hash = mjx_arm.load(RUN_MODEL).model_hash
    changed = {}
    for stage in STAGES:
        folder = run / stage
        stage_json = json.loads((folder / "stage.json").read_text())
        for path in sorted(folder.glob("translator_seed*.ckpt")):
            meta, _ = checkpoint.read(path)
            labels = labels_of(path, meta, stage_json, model_hash)
            if not missing_labels(meta) and all(meta[k] == labels[k] for k in LABELS):
                continue
            rel = str(path.relative_to(run))
            if check:
                changed[rel] = {"labels": labels}
                continue
            before = _sha256(path)
            out = checkpoint.rewrite_meta(path, labels)
            changed[rel] = {
                "labels": labels,
                "payload_sha256": out["payload_sha256"],
                "file_sha256_before": before,
                "file_sha256_after": _sha256(path),
            }
            log(f"labelled {rel}: {labels['method']} source -> {labels['target_domain']}")
    if changed and not check:
        record = run / RECORD
        old = json.loads(record.read_text()) if record.exists() else {}
        tmp = record.with_suffix(".tmp")
        tmp.write_text(json.dumps(old | changed, indent=1, sort_keys=True) + "\n")
        tmp.replace(record)
    return changed


def main(argv=None) -> None:
    """CLI: label the first run's translators, or with --check only report; a file that
    needs labels under --check exits with status 1."""
    p = cli_parser("ccgan.label_translators", __doc__)
    p.add_argument("--run", default=str(RUN_DIR), help="the chain's run folder")
    p.add_argument("--check", action="store_true", help="only report files without labels")
    a = p.parse_args(argv)
    changed = label_run(Path(a.run), check=a.check)
    if a.check and changed:
        raise SystemExit(f"unlabelled translator files: {', '.join(sorted(changed))}")
    print(f"{len(changed)} file(s) labelled" if not a.check else "every file is labelled")


if __name__ == "__main__":
    main()
