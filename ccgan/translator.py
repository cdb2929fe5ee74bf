"""A trained G_c packaged for use: D_s pressure programs in, D_c pressure programs out.

A translator is for one pair of media (D_s to D_c, or to the aged arm) at one hold factor k, or,
conditioned (issue 51, `ccgan.distill_range`), for a range of media: `translate(p, x,
target=Domain(...))` then gives the target's commands and the k the rule picks for it
(`ccgan.media_range`).
"""

from __future__ import annotations

import dataclasses
import functools
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ccgan import checkpoint
from ccgan.data import (
    PRESSURE_DIM,
    PoseBounds,
    denormalise_pose,
    denormalise_pressure,
    normalise_pose,
    normalise_pressure,
    samples,
)
from ccgan.media_range import MEDIA_RANGE, N_CONDITION, MediaRange
from ccgan.models import ForwardModel, Generator, forward_open_loop

_RESULTS = Path(__file__).resolve().parent.parent / "results"
#: The committed translators of the I-Support arm (models/softarm.xml,
#: `mjx_arm.constants.TRANSLATOR_MODEL_PATH`): the run folder of the chain's rerun
#: (`python -m experiments.paper`), one folder per stage (ccgan, wcgan, ccgan_sim, aged_sim; the
#: rerun made no aged CCGAN-GP).
TRANSLATORS_DIR = _RESULTS / "paper" / "rerun_2026-11-27" / "run"
#: The previous I-Support arm's translators (models/softarm_linear.xml, the linear law), the
#: chain's first run (stages ccgan, wcgan, ccgan_large, ccgan_sim, aged, aged_sim), kept for
#: comparison.
LINEAR_TRANSLATORS_DIR = _RESULTS / "paper" / "run"
#: The earlier solid-disc arm's translators (models/softarm_solid.xml), kept for comparison.
SOLID_TRANSLATORS_DIR = _RESULTS / "solid" / "translators"
#: Where `load_translator()` looks when given no path (override with $CCGAN_TRANSLATOR).
DEFAULT_PATH = TRANSLATORS_DIR / "ccgan" / "translator.ckpt"

#: Commands `Translator.translate` accepts (bar): the valves take [0, 3.5]; a little slack for
#: noise, and anything further out is in other units (kPa, psi, Pa) or garbage.
PRESSURE_RANGE_BAR = (-0.5, 5.0)
#: Largest tip distance from the origin (m) accepted: the arm is ~0.2 m long, so a pose beyond
#: this is in millimetres or centimetres.
MAX_TIP_DISTANCE_M = 2.0
#: Largest |norm(d3) - 1| accepted: d3 is the tip's unit tangent.
D3_NORM_TOLERANCE = 0.05
#: Largest command `Translator.predict_poses` accepts (bar): the valves saturate at 3.5 bar, so
#: a command above 10 bar is in other units (kPa, psi) rather than an over-driven valve.
MAX_COMMAND_BAR = 10.0

#: The methods a translator file records ("method" in its metadata): `ccgan.train`'s CCGAN-GP
#: and its WCGAN-GP baseline, and the stages that refine them in the simulator
#: (the retired `ccgan.finetune`, whose files `eval` refuses; `ccgan.distill`: "distill" when
#: it started from a CCGAN-GP translator, "distill_from_<method>" from another, whose file then
#: records "started_from").
#: `ccgan.distill_range`: a conditioned translator over a range of media, its target domain
#: label `ccgan.media_range.MEDIA_RANGE`.
METHODS = (
    "ccgan",
    "wcgan",
    "finetune",
    "distill",
    "distill_from_wcgan",
    "distill_from_finetune",
    "distill_range",
)
#: What a translator file says it is, each a metadata key: its method, the domains it translates
#: from and into (mjx_arm.DOMAINS names: "source" -> "constrained" or "aged") and the
#: `mjx_arm.Arm.model_hash` of the arm it was trained (or last refined) on; a translator
#: trained on the reference rod's data (`mjx_arm.babble --backend rod`) records the rod's
#: `mjx_arm.RodArm.model_hash` ("rod-...", `is_rod_trained`), never an MJCF's.
LABELS = ("method", "source_domain", "target_domain", "model_hash")
#: The flag of every command that loads translators which lets files without LABELS through.
TRUST_FLAG = "--trust-unlabelled-translators"
#: The key, in a distilled file's stage record (its metadata's "finetune"), of the arm it was
#: taught on when that was not its target domain itself but a Domain read from a file
#: (`ccgan.distill --teach-domain`, e.g. one identified from the target's data): {"path",
#: "sha256" (of the file), "method" (the identification's), "domain" (every Domain field),
#: "values" (`mjx_arm.domains.physical_values` of the taught arm)}. A file without it was
#: taught in its target itself (privileged), or not distilled; `taught_domain` reads it.
TAUGHT_DOMAIN = "taught_domain"


class TranslatorMismatchError(checkpoint.CheckpointError):
    """A translator file is labelled for another method, domain or arm than the one asked for."""


class UnlabelledTranslatorError(checkpoint.CheckpointError):
    """A translator file does not record what it is (`LABELS`) and was not trusted."""


def translator_labels(meta: dict) -> dict:
    """{label: value} of the `LABELS` a translator file's metadata records.

    Its model hash is the one of the last fine-tune stage that refined it, where one did (files
    written before the labels recorded the arm there, or only `ccgan.train`'s top-level one).
    """
    labels = {key: meta[key] for key in LABELS if key in meta}
    stage_hash = (meta.get("finetune") or {}).get("model_hash")
    if stage_hash:
        labels["model_hash"] = stage_hash
    return labels


def taught_domain(meta: dict) -> dict | None:
    """The record of the arm a translator file was last distilled on when that was a Domain
    read from a file (`TAUGHT_DOMAIN`: a translator built from the target's data alone); None
    when its last stage was taught in the target itself, or it was never distilled. Only the
    last stage counts: a file distilled again in the target is privileged again."""
    record = (meta.get("finetune") or {}).get(TAUGHT_DOMAIN)
    return record if isinstance(record, dict) else None


def is_rod_trained(labels: dict) -> bool:
    """Whether a translator file's labels (`translator_labels`) say it was trained (or last
    refined) on the reference rod's data: its model hash is a `mjx_arm.RodArm.model_hash`."""
    return str(labels.get("model_hash", "")).startswith("rod-")


def missing_labels(meta: dict) -> list[str]:
    """The `LABELS` a translator file's metadata does not record itself."""
    return [key for key in LABELS if key not in meta]


def check_labels(
    meta: dict,
    path="translator",
    *,
    method: str | tuple[str, ...] | None = None,
    source_domain: str | None = None,
    target_domain: str | None = None,
    model_hash: str | None = None,
    trust_unlabelled: bool = False,
) -> dict:
    """Refuses a translator file that is not what the caller expects; returns its labels.

    Args:
      meta: the file's metadata (`checkpoint.load`'s second item).
      path: the file, named in messages.
      method: the method (or methods, a tuple) it must have been made by (`METHODS`).
      source_domain, target_domain: the domains it must translate between.
      model_hash: the `Arm.model_hash` of the arm it must have been trained on.
        None for any of these: not checked.
      trust_unlabelled: let a file through that does not record every label (files written
        before labels: the solid-disc arm's); the labels it does record are still checked.

    Returns:
      `translator_labels(meta)`.

    Raises:
      UnlabelledTranslatorError: a label is not recorded and `trust_unlabelled` is False.
      TranslatorMismatchError: a label differs from the expected value; the message names both.
    """
    labels = translator_labels(meta)
    missing = missing_labels(meta)
    if missing and not trust_unlabelled:
        raise UnlabelledTranslatorError(
            f"{path} does not record its {', '.join(missing)} (written before translator files"
            " were labelled, like the solid-disc arm's in results/solid/translators/), so it"
            f" cannot be checked against this run: pass {TRUST_FLAG} (trust_unlabelled=True)"
            " to use it anyway"
        )
    wanted = {
        "method": method,
        "source_domain": source_domain,
        "target_domain": target_domain,
        "model_hash": model_hash,
    }
    for key, want in wanted.items():
        allowed = (want,) if isinstance(want, str) else tuple(want or ())
        if allowed and key in labels and labels[key] not in allowed:
            raise TranslatorMismatchError(
                f"{path} is a {describe_labels(labels)}, but this run expects {key}"
                f" {' or '.join(map(repr, allowed))}; the file has {labels[key]!r}"
            )
    return labels


def describe_labels(labels: dict) -> str:
    """ "ccgan translator source -> aged, arm 70c7aaddecf5fdd7" (what a file's labels tell)."""
    domains = f"{labels.get('source_domain', '?')} -> {labels.get('target_domain', '?')}"
    arm = labels.get("model_hash", "not recorded")
    return f"{labels.get('method', 'unknown-method')} translator {domains}, arm {arm}"


def check_program(pressures_bar, poses) -> tuple[np.ndarray, np.ndarray]:
    """Validates a D_s program before translation; returns float32 [T, 3] and [T, 6] copies.

    G_c squashes whatever it is given into valid commands, so inputs in the wrong units or with
    NaNs would come out as plausible-looking, wrong commands. Here they are refused instead.

    Args:
      pressures_bar: [T, 3] commands (bar).
      poses: [T, 6] tip position (m) then unit d3.

    Raises:
      TypeError: boolean pressures or poses (a mask passed for a program: True would read as
        1 bar).
      ValueError: naming the problem: shapes, an empty program, non-finite values (with the
        first bad step), pressures outside PRESSURE_RANGE_BAR, tip positions farther than
        MAX_TIP_DISTANCE_M from the origin, or d3 not of unit length.
    """
    for name, a in (("pressures", pressures_bar), ("poses", poses)):
        if np.asarray(a).dtype == np.bool_:
            raise TypeError(f"{name} are booleans: pass numbers (pressures in bar, poses in m)")
    p = np.asarray(pressures_bar, np.float32)
    x = np.asarray(poses, np.float32)
    if p.ndim != 2 or p.shape[1] != 3 or x.shape != (p.shape[0], 6):
        raise ValueError(f"need pressures [T, 3] and poses [T, 6], got {p.shape}, {x.shape}")
    if p.shape[0] == 0:
        raise ValueError("empty program: pressures and poses have T = 0 steps")
    for name, a in (("pressures", p), ("poses", x)):
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            raise ValueError(
                f"{name} have non-finite values (NaN or inf) at {int(bad.sum())} step(s),"
                f" first at step {int(np.argmax(bad))}"
            )
    low, high = PRESSURE_RANGE_BAR
    if p.min() < low or p.max() > high:
        raise ValueError(
            f"pressures span [{p.min():.4g}, {p.max():.4g}], outside the plausible"
            f" [{low}, {high}] bar: pass bar (not kPa, psi or Pa)"
        )
    reach = float(np.linalg.norm(x[:, :3], axis=1).max())
    if reach > MAX_TIP_DISTANCE_M:
        raise ValueError(
            f"tip positions reach {reach:.4g} from the origin, beyond {MAX_TIP_DISTANCE_M} m:"
            " pass metres (not mm or cm)"
        )
    norm = np.linalg.norm(x[:, 3:], axis=1)
    worst = int(np.argmax(np.abs(norm - 1.0)))
    if abs(norm[worst] - 1.0) > D3_NORM_TOLERANCE:
        raise ValueError(
            f"poses[:, 3:6] must be the unit d3 director; its norm is {norm[worst]:.4g} at"
            f" step {worst} (tolerance {D3_NORM_TOLERANCE})"
        )
    return p, x


def save_translator(
    path,
    g_c_params,
    k: int,
    bounds: PoseBounds,
    config,
    forward_c_params=None,
    forward_model: ForwardModel | None = None,
    model_hash: str | None = None,
    domains: tuple[str, str] | None = None,
) -> Path:
    """Writes G_c (and optionally F_c), k and the pose bounds to one checkpoint file.

    The file records its `LABELS`: the method (from `config.baseline`: "wcgan" or "ccgan"),
    `domains` (source, target: the training data's domain names) and `model_hash`
    (`mjx_arm.Arm.model_hash` of the arm the data was simulated with; the rod's
    `RodArm.model_hash` for the rod's data, whose config then names k_choice_simulator "rod"
    if k was chosen in a simulator), so that
    `load_translator` and the commands can refuse it for another method, domain or arm. Without
    `domains` or `model_hash` the file is unlabelled (`check_labels` refuses it unless trusted).
    """
    fwd = forward_model or ForwardModel()
    tree = {"g_c": g_c_params}
    if forward_c_params is not None:
        tree["f_c"] = forward_c_params
    meta = {
        "kind": "translator",
        "k": int(k),
        "bounds": bounds.to_dict(),
        "generator": config.generator_args,
        "forward": {"hidden": fwd.hidden, "fc": fwd.fc},
        "config": config.to_dict(),
        "method": "wcgan" if config.baseline else "ccgan",
    }
    if model_hash is not None:
        meta["model_hash"] = model_hash
    if domains is not None:
        meta["source_domain"], meta["target_domain"] = domains
    return checkpoint.save(path, tree, meta)


@dataclasses.dataclass
class Translator:
    """G_c with its hold factor k and the normalisation it was trained with.

    A conditioned translator (`media` set, `generator.n_condition` = 2) covers a range of media
    and needs a target: its k is the target's (`hold_factor`), and `k` is only the k of the
    translator it was started from (D_c's), kept for the file's format.
    """

    g_c_params: dict
    k: int
    bounds: PoseBounds
    generator: Generator
    f_c_params: dict | None = None
    forward_model: ForwardModel | None = None
    media: MediaRange | None = None

    @property
    def conditioned(self) -> bool:
        """Whether this translator takes a target medium (`translate(..., target=...)`)."""
        return self.media is not None

    def target_condition(self, target, t63_s: float | None = None) -> tuple[np.ndarray, int]:
        """(G_c's condition features [2], k) for a target of a conditioned translator.

        Args:
          target: an `mjx_arm.Domain` or (drag ratio r, stiffness scale s) inside the range
            (`ccgan.media_range.MediaRange.drag_and_stiffness`).
          t63_s: the target's measured 63% step time (s; one step test on the arm), which sets
            k by the rule; None: the step time the file's fit gives for (r, s).

        Raises:
          TypeError: this translator is for one pair of media (it takes no target), or the
            target is neither a Domain nor a pair (r, s), or none was given.
          ValueError: the target is outside the trained range, or a Domain the range cannot
            read, or t63_s is not a step time.
        """
        if self.media is None:
            raise TypeError(
                f"this translator is for one pair of media at k = {self.k}: it takes no"
                " target (pass target only to a conditioned translator, ccgan.distill_range)"
            )
        if target is None:
            r_range, s_range = self.media.drag_ratio_range, self.media.stiffness_range
            raise TypeError(
                "this translator is conditioned on the target medium: pass"
                " target=mjx_arm.Domain(...) or target=(drag ratio r, stiffness scale s), r in"
                f" {r_range}, s in {s_range}"
            )
        r, s = self.media.drag_and_stiffness(target)
        return self.media.condition(r, s), self.media.hold_factor(r, s, t63_s)

    @functools.cached_property
    def _generator_jit(self):
        """G_c's apply, jitted once per translator (compiled once per program length): run
        op by op, the main job's commands took 33 s on a 2-core CPU, jitted 2.8 s
        (`bench/results/cpu/main_job_fresh_clone.md`)."""
        return jax.jit(self.generator.apply)

    def translate(
        self, pressures_s, poses_s, target=None, *, t63_s: float | None = None
    ) -> tuple[np.ndarray, int]:
        """Translates a D_s program into D_c (or, conditioned, into the target medium).

        Args:
          pressures_s: [T, 3] D_s commands (bar, 10 Hz).
          poses_s: [T, 6] the D_s poses they produce (tip position m, unit d3).
          target: a conditioned translator's target medium, an `mjx_arm.Domain` or (drag ratio
            r, stiffness scale s) inside its range; None for a translator of one pair.
          t63_s: a conditioned translator's target's measured 63% step time (s), which sets k
            (`target_condition`); None: the file's fit of it.

        Returns:
          (pressures_c [T * k, 3] bar: each translated command held k control periods, k).

        Raises:
          TypeError: boolean pressures or poses (`check_program`); a target given to a
            translator of one pair, or none to a conditioned one (`target_condition`).
          ValueError: the program fails `check_program` (shapes, NaN/inf, units); the target
            is outside the trained range (`target_condition`).
        """
        condition, k = (None, self.k)
        if self.conditioned or target is not None or t63_s is not None:
            condition, k = self.target_condition(target, t63_s)
        p, x = check_program(pressures_s, poses_s)
        s = samples(p, x, self.bounds)
        if condition is not None:
            s = with_condition(s, condition)
        out = np.asarray(self._generator_jit(self.g_c_params, jnp.asarray(s[None])))[0]
        commands = denormalise_pressure(out[:, :PRESSURE_DIM]).astype(np.float64)
        return np.repeat(commands, k, axis=0), k

    def predict_poses(self, pressures_c, pose0) -> np.ndarray:
        """F_c's open-loop poses [T', 6] (m, unit d3) for D_c commands [T', 3] (bar) from pose0 [6].

        Raises:
          ValueError: the file held no F_c; commands not [T', 3], empty, non-finite, or above
            MAX_COMMAND_BAR (in kPa or psi, not bar); pose0 not [6] or non-finite.
        """
        if self.f_c_params is None:
            raise ValueError("this translator was saved without F_c")
        p_bar = np.asarray(pressures_c, np.float32)
        x0 = np.asarray(pose0, np.float32)
        if p_bar.ndim != 2 or p_bar.shape[1] != PRESSURE_DIM or p_bar.shape[0] == 0:
            raise ValueError(f"need commands [T, 3] with T >= 1 (bar), got {p_bar.shape}")
        if x0.shape != (6,):
            raise ValueError(f"need pose0 [6] (tip m, unit d3), got {x0.shape}")
        for name, a in (("commands", p_bar), ("pose0", x0)):
            if not np.isfinite(a).all():
                raise ValueError(f"{name} have non-finite values (NaN or inf)")
        if np.abs(p_bar).max() > MAX_COMMAND_BAR:
            raise ValueError(
                f"commands reach {np.abs(p_bar).max():.4g}, beyond {MAX_COMMAND_BAR} bar (the"
                " valves saturate at 3.5 bar): pass bar, not kPa or psi"
            )
        p = jnp.asarray(normalise_pressure(p_bar))[None]
        x0 = jnp.asarray(normalise_pose(x0, self.bounds))[None]
        pred = forward_open_loop(self.forward_model, self.f_c_params, p, x0)
        return denormalise_pose(np.asarray(pred[0], np.float64), self.bounds)


def with_condition(samples_s: np.ndarray, condition) -> np.ndarray:
    """Samples [..., T, 9] with the condition [..., C] (one per program, or [C] for all)
    appended at every step: [..., T, 9 + C] float32, a conditioned G_c's input."""
    samples_s = np.asarray(samples_s, np.float32)
    condition = np.asarray(condition, np.float32)
    steps = np.broadcast_to(condition[..., None, :], samples_s.shape[:-1] + (condition.shape[-1],))
    return np.concatenate([samples_s, steps], -1)


def translator_path(path: str | os.PathLike | None = None) -> Path:
    """The file `load_translator(path)` reads: path, else $CCGAN_TRANSLATOR, else DEFAULT_PATH.

    Only None means "the default": an empty path is an error rather than a silent fall-back
    to the default file (an unset shell variable in `--ccgan-path "$X"` would otherwise
    evaluate the wrong translator). An empty $CCGAN_TRANSLATOR counts as unset.

    Raises:
      ValueError: `path` is an empty string.
    """
    if path is not None:
        if not str(path):
            raise ValueError("empty translator path; pass None for the default translator")
        return Path(path)
    return Path(os.environ.get("CCGAN_TRANSLATOR") or DEFAULT_PATH)


def load_translator(
    path: str | os.PathLike | None = None,
    *,
    method: str | tuple[str, ...] | None = None,
    source_domain: str | None = None,
    target_domain: str | None = None,
    model_hash: str | None = None,
    trust_unlabelled: bool = False,
) -> Translator:
    """Loads a translator file (default: $CCGAN_TRANSLATOR or DEFAULT_PATH) that is what it
    is expected to be.

    Args:
      path: the file (`translator_path`).
      method, source_domain, target_domain, model_hash: what the file must record
        (`check_labels`), e.g. `target_domain="aged", model_hash=arm.model_hash`; None: any.
      trust_unlabelled: accept a file that records no labels (the solid-disc arm's).

    Raises:
      ValueError: `path` is an empty string.
      FileNotFoundError: no file at the path (`checkpoint.CheckpointNotFoundError`, naming it).
      ccgan.checkpoint.CheckpointError: corrupt, or not a translator file.
      TranslatorMismatchError, UnlabelledTranslatorError: (CheckpointErrors) the file is labelled
        otherwise than expected, or not labelled and not trusted (`check_labels`).
    """
    path = translator_path(path)
    source = checkpoint.load(path)
    check_labels(
        source[1],
        path,
        method=method,
        source_domain=source_domain,
        target_domain=target_domain,
        model_hash=model_hash,
        trust_unlabelled=trust_unlabelled,
    )
    return translator_from_checkpoint(source, path)


def translator_from_checkpoint(source: tuple[dict, dict], path="checkpoint") -> Translator:
    """The translator of a loaded translator file (`checkpoint.load`'s (tree, meta) pair).

    Raises:
      ccgan.checkpoint.CheckpointError: not a translator file (`path` names it in the message).
    """
    tree, meta = source
    if meta.get("kind") != "translator":
        raise checkpoint.CheckpointError(f"{path} is not a translator checkpoint")
    k = meta.get("k")
    if not isinstance(k, int) or isinstance(k, bool) or k < 1:
        raise checkpoint.CheckpointError(f"{path}: hold factor k must be an int >= 1, got {k!r}")
    try:
        generator = Generator(**meta["generator"])
        media = MediaRange.from_dict(meta[MEDIA_RANGE]) if MEDIA_RANGE in meta else None
        translator = Translator(
            g_c_params=tree["g_c"],
            k=k,
            bounds=PoseBounds.from_dict(meta["bounds"]),
            generator=generator,
            f_c_params=tree.get("f_c"),
            forward_model=ForwardModel(**meta["forward"]),
            media=media,
        )
    except (KeyError, TypeError, ValueError) as err:
        raise checkpoint.CheckpointError(f"{path}: incomplete translator file ({err!r})") from err
    if generator.n_condition != (N_CONDITION if media is not None else 0):
        raise checkpoint.CheckpointError(
            f"{path}: its G_c takes {generator.n_condition} condition features, and the file"
            f" {'records' if media is not None else 'records no'} range of media"
            f" ({MEDIA_RANGE!r} metadata): a conditioned G_c needs both, {N_CONDITION} features"
        )
    return translator
