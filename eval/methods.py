"""The evaluation's methods: their names, the translator checkpoints and how each method's D_c
commands are made.

Methods:
  none     D_s pressures straight into D_c (k = 1).
  stretch  D_s pressures, each held k periods; k minimises the tracking error on a separate
           validation program (`mjx_arm.programs.validation_program`), searched over
           EvalConfig.hold_factors = {1, 5, 10, ..., 30}: the GAN's set {5, ..., 30} plus 1.
  ccgan    the trained CCGAN-GP translator `ccgan.load_translator(path)`. Every translator
           method is skipped with a note when its default checkpoint is absent; one that was
           asked for (--ccgan-path etc.) must load, or the run stops before any work.
  ccgan_sim  "distilled" in every table, plot, video and help text: the CCGAN-GP translator
           distilled in the simulator (`ccgan.distill`, by imitation of `tracking.mpc`;
           docs/training.md), its file labelled "distill":
           results/paper/rerun_2026-11-27/run/ccgan_sim/translator.ckpt or --distilled-path
           (--ccgan-sim-path and the method name "distilled" are accepted too); the project's
           best translator, so the main job shows it beside CCGAN-GP and stretch only. The key
           stays ccgan_sim: the committed runs' shapes.json and stage folders use it.
  wcgan    the WCGAN-GP baseline translator: a translator checkpoint given by --wcgan-path or
           found at results/paper/rerun_2026-11-27/run/wcgan/translator.ckpt.
  ccgan_ident  "distilled (identified arm)": a CCGAN-GP translator distilled on an arm identified
           from the target's babbling data (`ccgan.distill --teach-domain`, k chosen there;
           docs/identification.md), its file labelled "distill" for --target-domain and
           recording the Domain file it was taught on ("taught_domain"): --identified-path, or
           results/paper/rerun_2026-11-27/run/ident_sim/translator.ckpt where a chain made one.
           Scored, like every method, in the true target; its k is the one it holds. The
           data-only counterpart of ccgan_sim, which was taught in the true target (privileged):
           a file taught on a Domain file is refused as ccgan_sim, one taught in the target is
           refused as ccgan_ident.
  ccgan_range  "distilled (range)": the conditioned translator over a range of media
           (`ccgan.distill_range`, issue 51; docs/media_range.md), its file labelled
           "distill_range" for target "media_range" whatever the run's target: --range-path, or
           results/paper/rerun_2026-11-27/run/media_range/translator.ckpt (none is committed).
           It translates into the run's own D_c, the built-in Domain of --target-domain
           (constrained: drag ratio r = 10, stiffness s = 1; aged: r = 10, s = 0.7) or the Domain
           of --target-domain-file, at the k its rule gives that medium (`Translator.translate(...,
           target=Domain)`); a medium outside its range is refused when it loads. shapes.json's
           "translator_labels" record the (r, s) and k ("medium"). Not in the default methods.
  mpc      receding-horizon tracking in the D_c simulator itself (`tracking.mpc.track`, MuJoCo C,
           k = the stretch k): at every source step the next command is planned by Gauss-Newton
           on the simulated tracking error and applied. Not a translator (it needs the D_c
           simulator at translation time); a model-based reference. Not in the default methods.
  oracle   D_c commands optimised directly through the differentiable MJX rollout with
           optax Adam (`tracking.oracle`; k = the stretch k), commands kept in the valve range by
           a sigmoid, starting from the mpc commands (OracleConfig.init; "stretch" starts from
           the stretch program); a lower reference for the other methods. Like every
           translator's output, one command per source step held k periods (OracleConfig.held;
           --oracle-per-period frees every control period). All shapes are
           optimised together (one vmapped rollout). Gradients through thousands of MJX steps
           are slow, so the oracle optimises (and every method's ratio to it is computed over)
           the first `OracleConfig.horizon_s` seconds only, and the CLI leaves it out on CPU
           unless asked: five 2 s programs at k = 10 (5,000 physics steps each), 10 Adam steps,
           took 500 s on a 2-core CPU, compile included (results/full at commit 7e006b8); on an H200
           the first step took 98 s and each further one 11.6 s (bench/results/h200/oracle.md).

The default checkpoints (`ccgan.translator.TRANSLATORS_DIR`) translate into the constrained
domain whatever the target domain: with --target-domain aged they are refused as labelled for
another domain (`load_translator`), before any work; the aged pair's are given by path.

A translator checkpoint is read by `ccgan.translator.Translator`, the one translator class.
`TranslatorMethod` is not a translator: it is an evaluation method backed by one, adding what the
evaluation needs on top of any object with a `translate`: the seed (a sampling translator draws
with it, one trained model per seed is picked by it), a check of the commands' shape, and the
arms its files record.
"""

from __future__ import annotations

import dataclasses
import inspect
import os
from pathlib import Path

import numpy as np

from ccgan.media_range import MEDIA_RANGE
from ccgan.translator import TRANSLATORS_DIR
from mjx_arm import domains
from tracking.held import stretch

METHODS = (
    "none",
    "stretch",
    "ccgan",
    "ccgan_sim",
    "wcgan",
    "mpc",
    "oracle",
    "ccgan_ident",
    "ccgan_range",
)
#: What runs without --methods (the oracle is left out on CPU).
DEFAULT_METHODS = ("none", "stretch", "ccgan", "ccgan_sim", "wcgan", "oracle")
TRANSLATOR_METHODS = ("ccgan", "ccgan_sim", "wcgan", "ccgan_ident", "ccgan_range")
#: Each method's one name, in tables, plots, videos, notes and help.
METHOD_NAMES = {
    "none": "untranslated",
    "stretch": "stretch only",
    "ccgan": "CCGAN-GP",
    "ccgan_sim": "distilled",
    "wcgan": "WCGAN-GP",
    "mpc": "tracker",
    "oracle": "oracle",
    "ccgan_ident": "distilled (identified arm)",
    "ccgan_range": "distilled (range)",
}
#: Other names a command line accepts for a method (--methods, --robust-methods).
METHOD_ALIASES = {"distilled": "ccgan_sim"}
#: Where the simulator-fine-tuned CCGAN-GP is looked for when no path is given.
CCGAN_SIM_DEFAULT_PATH = TRANSLATORS_DIR / "ccgan_sim" / "translator.ckpt"
#: Where the WCGAN-GP baseline's translator checkpoint is looked for when no path is given.
WCGAN_DEFAULT_PATH = TRANSLATORS_DIR / "wcgan" / "translator.ckpt"
#: Where the translator distilled on the identified arm is looked for when no path is given
#: (the chain's ident_sim stage; absent until a run with it is committed).
IDENT_DEFAULT_PATH = TRANSLATORS_DIR / "ident_sim" / "translator.ckpt"
#: Where the conditioned translator over a range of media is looked for when no path is given
#: (absent until a run with one is committed; `ccgan.distill_range --out DIR` writes
#: DIR/translator_seed<s>.ckpt).
RANGE_DEFAULT_PATH = TRANSLATORS_DIR / "media_range" / "translator.ckpt"
#: The flag that gives each translator method's checkpoint, named in notes and errors.
PATH_FLAGS = {
    "ccgan": "--ccgan-path",
    "wcgan": "--wcgan-path",
    "ccgan_sim": "--distilled-path",
    "ccgan_ident": "--identified-path",
    "ccgan_range": "--range-path",
}
#: The "method" a translator file must record (`ccgan.translator.LABELS`) to be scored as each
#: translator method: a WCGAN-GP file is never reported as CCGAN-GP, a trained one never as
#: distilled, and a translator distilled from another start (`ccgan.distill` labels it
#: "distill_from_<start method>", e.g. "distill_from_wcgan") never as the distilled CCGAN-GP.
FILE_METHODS = {
    "ccgan": ("ccgan",),
    "wcgan": ("wcgan",),
    "ccgan_sim": ("distill",),
    "ccgan_ident": ("distill",),
    "ccgan_range": ("distill_range",),
}
#: The target domain a translator method's files must record when it is not the run's own
#: (cfg.target_domain, or "identified" with a Domain file): a conditioned translator's is the
#: range's label, whatever medium it is scored in (`CONDITIONED_METHODS`).
FILE_TARGETS = {"ccgan_range": MEDIA_RANGE}
#: The translator methods that take the run's D_c as their target (`TranslatorMethod.target`).
CONDITIONED_METHODS = ("ccgan_range",)
#: The distilled methods, by what taught them: ccgan_ident's files must record the Domain file
#: they were taught on (`ccgan.translator.taught_domain`), ccgan_sim's must not (taught in the
#: target itself), so that neither is reported as the other.
TAUGHT_ON_FILE = {"ccgan_sim": False, "ccgan_ident": True}
#: Methods whose translator files are no longer scored: the label -> why.
RETIRED_FILE_METHODS = {
    "finetune": "ccgan.finetune, a method retired for the distillation (its numbers are kept"
    " in docs/ccgan_study.md); distil the CCGAN-GP translator with ccgan.distill instead",
}


class TranslatorError(ValueError):
    """A translator checkpoint that was asked for (a path, or $CCGAN_TRANSLATOR) is missing or
    does not load; the run stops before any work instead of skipping the method."""


def translator_source(method: str, cfg) -> tuple[Path, bool]:
    """(checkpoint file, whether it was asked for) of a translator method.

    `cfg` is an `eval.pipeline.EvalConfig` (not imported: the pipeline imports this module).

    Asked for: a path in cfg, or for ccgan also $CCGAN_TRANSLATOR (`ccgan.translator_path`);
    otherwise the method's default file, which may be absent.
    """
    if method == "ccgan":
        from ccgan.translator import translator_path

        asked = cfg.ccgan_path is not None or bool(os.environ.get("CCGAN_TRANSLATOR"))
        return translator_path(cfg.ccgan_path), asked
    given, default = {
        "ccgan_sim": (cfg.ccgan_sim_path, CCGAN_SIM_DEFAULT_PATH),
        "wcgan": (cfg.wcgan_path, WCGAN_DEFAULT_PATH),
        "ccgan_ident": (cfg.ccgan_ident_path, IDENT_DEFAULT_PATH),
        "ccgan_range": (cfg.ccgan_range_path, RANGE_DEFAULT_PATH),
    }[method]
    return Path(given or default), given is not None


class TranslatorMethod:
    """An evaluation method backed by translators: `translate(p_s [T, 3], poses_s [T, 6], seed)`.

    With `trained_seeds` ({seed: translator}, several independently trained models) the seed
    picks the model, so a method's mean ± std spans training seeds. `model_hashes` holds the
    `Arm.model_hash`es its files record as the arm they were trained on (files written before
    that was recorded add none); `files` the checkpoint files loaded, the main one first, and
    `labels` what each records of itself (`ccgan.translator.translator_labels`, with
    "started_from" where a distillation recorded its start and "taught_domain" where it was
    taught on a Domain file), for the report; a conditioned translator's (`CONDITIONED_METHODS`)
    add "medium", the (r, s) and k it translates into (`medium_record`).

    With `target` (an `mjx_arm.Domain`, the run's D_c) every translation is
    `translate(p_s, poses_s, target=target)`: a conditioned translator's, which returns the k
    its rule gives that medium; None for a translator of one pair.
    """

    def __init__(
        self,
        name: str,
        obj,
        trained_seeds: dict | None = None,
        model_hashes: frozenset = frozenset(),
        files: tuple[Path, ...] = (),
        labels: tuple[dict, ...] = (),
        target=None,
    ):
        self.name = name
        self.target = target
        self.files = tuple(Path(f) for f in files)
        self.labels = tuple(labels)
        self._obj = obj
        self.trained_seeds = trained_seeds or {}
        self.model_hashes = frozenset(model_hashes)
        try:
            params = inspect.signature(obj.translate).parameters
        except (TypeError, ValueError):
            params = {}
        self.takes_seed = "seed" in params or bool(self.trained_seeds)

    def translate(self, pressures_s: np.ndarray, poses_s: np.ndarray, seed: int):
        """Returns (D_c commands [T * k, 3] bar, k)."""
        medium = {} if self.target is None else {"target": self.target}
        if self.trained_seeds:
            out = self.trained_seeds[seed].translate(pressures_s, poses_s, **medium)
        elif self.takes_seed:
            out = self._obj.translate(pressures_s, poses_s, seed=seed, **medium)
        else:
            out = self._obj.translate(pressures_s, poses_s, **medium)
        commands, k = out
        commands = np.asarray(commands, dtype=np.float64)
        k = int(k)
        if commands.shape != (pressures_s.shape[0] * k, 3):
            raise ValueError(
                f"{self.name}.translate returned {commands.shape}, expected"
                f" ({pressures_s.shape[0] * k}, 3) for k = {k}"
            )
        return commands, k


def load_translator(method: str, cfg, target_file=None) -> tuple[TranslatorMethod | None, str]:
    """Loads a translator method's checkpoint (`translator_source`) with `ccgan.load_translator`.

    Only a default checkpoint may be absent: then (None, a note naming the file and the flag that
    gives another). One that was asked for (`translator_source`) and is absent, or any that does
    not load, raises, so a run never reports a table without the method it was asked to score.
    Every file must be labelled (`ccgan.translator.check_labels`) as made by the method
    (`FILE_METHODS`; a retired method's file is refused as such, `RETIRED_FILE_METHODS`) from
    "source" into cfg.target_domain, and a distilled one as taught on a Domain file or in the
    target as its method requires (`TAUGHT_ON_FILE`); a file without labels (the solid-disc
    arm's) loads only with cfg.trust_unlabelled_translators. The arms the files record go into
    `TranslatorMethod.model_hashes`, for `check_translator_arms`.

    With cfg.target_domain_file (D_c a Domain read from a file, named "identified") a file must
    be labelled for target "identified" (`ccgan.distill --domain identified --teach-domain`, as
    `ccgan.adapt` makes), and the Domain file it was taught on must hold the same Domain fields
    as cfg's (`check_taught_medium`): the same medium, whatever the files' paths, layouts or
    bytes. A file labelled for a built-in domain (constrained, aged) is refused, as it is for
    the other built-in one, even where its medium has the same values: labels name targets, and
    a file's numbers are only compared where its label is "identified". A labelled file is
    refused either way; cfg.trust_unlabelled_translators lets through only files without labels.

    A conditioned method's files (`CONDITIONED_METHODS`: ccgan_range) must be labelled for
    their range (`FILE_TARGETS`: "media_range") whatever the run's target, and must cover the
    run's D_c (the built-in Domain of cfg.target_domain, or cfg.target_domain_file's): its
    Domain is read as (r, s) and given k by each file's rule here (`medium_record`, the labels'
    "medium"), and becomes `TranslatorMethod.target`.

    Args:
      method: one of TRANSLATOR_METHODS.
      cfg: an `eval.pipeline.EvalConfig`; its paths and seeds are read.
      target_file: the `mjx_arm.domains.DomainFile` of cfg.target_domain_file as already read
        (`eval.target.read_target_file`); None reads it here.

    Returns:
      (translator, "loaded" or what was loaded) or (None, why).

    Raises:
      TranslatorError: an asked-for checkpoint is absent, a checkpoint does not load, or it is
        labelled for another method or domain, taught otherwise than its method says or on
        another medium than cfg.target_domain_file's, or not labelled and not trusted; a
        conditioned translator whose range does not hold the run's D_c.
    """
    path, asked = translator_source(method, cfg)
    if cfg.target_domain_file is not None and target_file is None:
        target_file = domains.read_domain_file(cfg.target_domain_file)
    target = cfg.target_domain if target_file is None else domains.IDENTIFIED
    medium = None
    if method in CONDITIONED_METHODS:
        medium = domains.resolve(cfg.target_domain) if target_file is None else target_file.domain
    target = FILE_TARGETS.get(method, target)
    given = (
        f"--target-domain {cfg.target_domain}"
        if target_file is None
        else f"--target-domain-file {cfg.target_domain_file}"
    )
    flag = PATH_FLAGS[method] + (" or $CCGAN_TRANSLATOR" if method == "ccgan" else "")
    if not path.is_file():
        if asked:
            raise TranslatorError(f"{method}: no translator checkpoint at {path} ({flag})")
        return None, f"no translator at its default {path} (give one with {flag})"
    from ccgan import checkpoint
    from ccgan.translator import (
        TranslatorMismatchError,
        UnlabelledTranslatorError,
        check_labels,
        taught_domain,
        translator_from_checkpoint,
    )

    hashes, loaded_files, file_labels = set(), [], []

    def checked(file: Path):
        """The translator in `file` (as `ccgan.load_translator` reads it); notes its arm."""
        try:
            source = checkpoint.load(file)
            recorded = source[1].get("method") if isinstance(source[1], dict) else None
            if recorded in RETIRED_FILE_METHODS:
                raise TranslatorError(
                    f"{method} ({PATH_FLAGS[method]}): {file} is labelled {recorded!r}:"
                    f" {RETIRED_FILE_METHODS[recorded]}"
                )
            translator = translator_from_checkpoint(source, file)
            labels = check_labels(
                source[1],
                file,
                method=FILE_METHODS[method],
                source_domain="source",
                target_domain=target,
                trust_unlabelled=cfg.trust_unlabelled_translators,
            )
            taught = taught_domain(source[1])
            _check_taught(method, file, taught)
            if target_file is not None and labels.get("target_domain") == domains.IDENTIFIED:
                check_taught_medium(
                    method, file, taught, target_file, getattr(cfg, "taught_medium_rtol", 0.0)
                )
        except TranslatorMismatchError as err:
            raise TranslatorError(f"{method} ({PATH_FLAGS[method]}, {given}): {err}") from err
        except UnlabelledTranslatorError as err:
            raise TranslatorError(f"{method}: {err}") from err
        except TranslatorError:
            raise
        except Exception as err:  # noqa: BLE001  (any failure to load is this error)
            raise TranslatorError(
                f"{method}: {file} does not load ({type(err).__name__}: {err})"
            ) from err
        into = {} if medium is None else {"medium": medium_record(method, file, translator, medium)}
        hashes.add(labels.get("model_hash"))
        loaded_files.append(file)
        started_from = source[1].get("started_from")
        file_labels.append(
            labels
            | ({"started_from": started_from} if started_from else {})
            | ({"taught_domain": taught} if taught else {})
            | into
        )
        return translator

    obj = checked(path)
    # Separately trained seeds beside the checkpoint (`ccgan.train --seeds 0 1 2` writes
    # translator_seed{s}.ckpt): used when there is one for every evaluation seed.
    seeds, why = {}, "loaded"
    if len(cfg.seeds) > 1:
        files = {s: path.parent / f"translator_seed{s}.ckpt" for s in cfg.seeds}
        if all(f.exists() for f in files.values()):
            seeds = {s: checked(f) for s, f in files.items()}
            why = f"loaded, trained seeds {list(cfg.seeds)}"
    model_hashes = frozenset(hashes - {None})
    return TranslatorMethod(
        method, obj, seeds, model_hashes, tuple(loaded_files), tuple(file_labels), medium
    ), why


def medium_record(method: str, file: Path, translator, medium) -> dict:
    """What a conditioned translator (`ccgan.translator.Translator` with a range) makes of the
    run's D_c `medium` (an `mjx_arm.Domain`): {"drag_ratio": r, "stiffness_scale": s, "k": the
    rule's k, "t63_s": the 63% step time (s) its file's fit gives, "role": "training",
    "held out" or "other" (`eval.media_range.role`), "range": {"drag_ratio", "stiffness_scale"}}.

    Raises:
      TranslatorError: the file records no range, or the medium is outside it or not one it can
        read (an absolute viscosity, another mass); the message names the method, the medium and
        the range.
    """
    from eval.media_range import role

    try:
        _, k = translator.target_condition(medium)
        r, s = translator.media.drag_and_stiffness(medium)
    except (TypeError, ValueError) as err:
        span = (
            ""
            if translator.media is None
            else f" (its range: drag ratio r {list(translator.media.drag_ratio_range)}, stiffness"
            f" scale s {list(translator.media.stiffness_range)})"
        )
        raise TranslatorError(
            f"{method} ({PATH_FLAGS[method]}): {file} cannot translate into this run's D_c,"
            f" {_medium_words(medium, translator)}{span}: {err}"
        ) from err
    return {
        "drag_ratio": r,
        "stiffness_scale": s,
        "k": int(k),
        "t63_s": translator.media.step_time.t63_s(r, s),
        "role": role(translator, r, s),
        "range": {
            "drag_ratio": list(translator.media.drag_ratio_range),
            "stiffness_scale": list(translator.media.stiffness_range),
        },
    }


def _medium_words(medium, translator) -> str:
    """ "the Domain 'identified' (viscosity_scale 1207.01, drag ratio r = 600, stiffness_scale
    1.0)": the medium's fields that are set (or are read as r and s), and its r."""
    fields = dataclasses.asdict(medium)
    default = dataclasses.asdict(domains.Domain())
    shown = [
        f"{key} {value!r}"
        for key, value in fields.items()
        if key != "name"
        and (value != default[key] or key in ("viscosity_scale", "stiffness_scale"))
    ]
    if translator.media is not None and medium.viscosity is None:
        from mjx_arm import media

        scale = medium.viscosity_scale or translator.media.constrained_viscosity_scale
        ratio = media.drag_ratio_of(scale, translator.media.constrained_viscosity_scale)
        shown.insert(1, f"drag ratio r = {ratio:.4g}")
    return f"the Domain {medium.name!r} ({', '.join(shown)})"


def _check_taught(method: str, file: Path, taught: dict | None) -> None:
    """Refuses a distilled file taught otherwise than `method` reports (`TAUGHT_ON_FILE`)."""
    if method not in TAUGHT_ON_FILE or TAUGHT_ON_FILE[method] == (taught is not None):
        return
    if taught is None:
        why = (
            "was taught in its target domain itself (no taught_domain record): it is the"
            f" privileged distilled translator; score it as ccgan_sim ({PATH_FLAGS['ccgan_sim']})"
        )
    else:
        why = (
            f"was taught on the Domain file {taught.get('path')} (sha256"
            f" {str(taught.get('sha256'))[:12]}), not in its target: score it as ccgan_ident"
            f" ({PATH_FLAGS['ccgan_ident']})"
        )
    raise TranslatorError(f"{method} ({PATH_FLAGS[method]}): {file} {why}")


def check_taught_medium(
    method: str, file: Path, taught: dict | None, target_file, rtol: float = 0.0
) -> None:
    """Refuses a file labelled "identified" unless the Domain it was taught on (its
    `ccgan.translator.taught_domain` record's "domain": every Domain field) holds the same fields
    as `target_file`'s Domain (an `mjx_arm.domains.DomainFile`, the eval's D_c): an "identified"
    translator is meant for the one medium it was taught on, and two Domain files of other
    paths, layouts (identify.json or plain) or bytes with the same fields are the same medium.
    With rtol > 0 (`EvalConfig.taught_medium_rtol`) each numeric field may differ by that much,
    relative to the target's: a translator built from data, taught on the identified medium,
    scored in the true one.

    Raises:
      TranslatorError: no taught record (its medium is unknown) or other fields, naming both.
    """
    want = dataclasses.asdict(target_file.domain)
    recorded = (taught or {}).get("domain")
    if recorded == want:
        return
    if isinstance(recorded, dict) and set(recorded) == set(want) and rtol > 0:

        def near(a, b) -> bool:
            if isinstance(a, (int, float)) and isinstance(b, (int, float)) and b != 0:
                return abs(a - b) <= rtol * abs(b)
            return a == b

        if all(near(recorded[k], want[k]) for k in want if k != "name"):
            return
    flags = f"{PATH_FLAGS[method]}, --target-domain-file {target_file.path}"
    if not isinstance(recorded, dict):
        raise TranslatorError(
            f"{method} ({flags}): {file} is labelled for target {domains.IDENTIFIED!r} but"
            " records no Domain file it was taught on, so its medium is unknown"
        )
    differ = sorted(k for k in set(want) | set(recorded) if want.get(k) != recorded.get(k))
    shown = ", ".join(f"{k} {recorded.get(k)!r} (here {want.get(k)!r})" for k in differ)
    allowed = f" (more than --taught-medium-rtol {rtol:g})" if rtol > 0 else ""
    raise TranslatorError(
        f"{method} ({flags}): {file} was taught on the Domain file {taught.get('path')} (sha256"
        f" {str(taught.get('sha256'))[:12]}), another medium than this run's{allowed}: {shown}"
    )


def check_translator_arms(translators: dict, arm, *also) -> None:
    """Refuses translators whose files record training on another arm than `arm` (or one of
    `also`: with --simulator rod the rod, `eval.rod`, whose own-data translators are scored).

    Raises:
      TranslatorError: a file records another `Arm.model_hash` (another MJCF: e.g. the soft arm
        for translators of the solid-disc one), which would score them on an arm they never saw.
    """
    accepted = [a.model_hash for a in (arm, *also)]
    for method, tr in translators.items():
        other = sorted(tr.model_hashes - set(accepted))
        if not other:
            continue
        if also:
            evaluated = f"the arms accepted have {' and '.join(accepted)}"
        else:
            evaluated = f"the arm evaluated has {arm.model_hash}"
        hint = "choose the arm with --model"
        if any(h.startswith("rod-") for h in other) and not also:
            hint = "a translator of the rod's data: score it with --simulator rod"
        raise TranslatorError(
            f"{method}: trained on the arm with model hash {', '.join(other)}, but"
            f" {evaluated} ({hint})"
        )


def forward_model(translators: dict[str, TranslatorMethod]):
    """The CCGAN-GP checkpoint's translator when it carries a learned forward model F_c
    (`predict_poses(commands [N, 3] bar, pose0 [6]) -> poses [N, 6]`), else None.

    The paper scored its translations through F_c, so the evaluation scores every method's D_c
    commands through it too, beside the simulator.
    """
    model = getattr(translators.get("ccgan"), "_obj", None)
    if model is not None and getattr(model, "f_c_params", None) is None:
        return None
    return model


def method_seeds(method: str, translators: dict[str, TranslatorMethod], seeds) -> list[int]:
    """The seeds a method runs: all of `seeds` for a translator that takes one (it samples, or
    has one trained model per seed), else the first only (the method is deterministic)."""
    stochastic = method in translators and translators[method].takes_seed
    return list(seeds) if stochastic else list(seeds[:1])


def method_commands(
    method: str,
    pressures_s: np.ndarray,
    poses_s: np.ndarray,
    seed: int,
    translators: dict[str, TranslatorMethod],
    k_stretch: int,
    mpc_commands: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """(D_c commands [T * k, 3] bar, k) of one method for a D_s program [T, 3] (bar) with its
    target poses [T, 6].

    Args:
      k_stretch: the validated stretch factor (control periods per source step) of stretch and
        mpc.
      mpc_commands: mpc's commands for this shape [T * k_stretch, 3] (bar), planned beforehand
        for every shape at once; only read for "mpc". The oracle is not made here (it optimises
        every shape together, see `tracking.oracle`).
    """
    if method == "none":
        return np.asarray(pressures_s), 1
    if method == "stretch":
        return stretch(pressures_s, k_stretch), k_stretch
    if method == "mpc":
        return mpc_commands, k_stretch
    return translators[method].translate(pressures_s, poses_s, seed)


def taught_domains(translators: dict[str, TranslatorMethod], arm_s, arm_c) -> dict:
    """{method: what its files record they were taught on, beside the truth} for the translators
    distilled on a Domain file (`ccgan.translator.taught_domain`, e.g. ccgan_ident): {"files":
    {file: the Domain file's sha256}, "path", "sha256", "method" and "values" of the first file's
    record, "truth": the physical values of the target the table is scored in
    (`mjx_arm.domains.physical_values` of `arm_c`, the chain in cfg.target_domain or in the
    Domain of cfg.target_domain_file; `arm_s` its source) and "error_pct": each identified value
    against it}. Empty when none was."""
    truth = domains.physical_values(arm_c.mj_model, arm_s.mj_model, arm_c.domain)
    out = {}
    for method, tr in translators.items():
        records = [labels.get("taught_domain") for labels in tr.labels]
        if not any(records):
            continue
        first = next(r for r in records if r)
        values = first.get("values") or {}
        files = zip(tr.files, records, strict=True)
        out[method] = {
            "files": {str(f): (r or {}).get("sha256") for f, r in files},
            **{key: first.get(key) for key in ("path", "sha256", "method", "domain")},
            "values": values,
            "truth": truth,
            "error_pct": {
                name: 100.0 * (values[name] / truth[name] - 1.0)
                for name in truth
                if isinstance(values.get(name), int | float)
            },
        }
    return out
