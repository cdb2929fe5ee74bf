"""The medium an evaluation scores in, where it is not a built-in domain name: a Domain read
from a JSON file (`EvalConfig.target_domain_file`: checked, read once, recorded in shapes.json),
and the note on the medium a conditioned translator (`ccgan_range`) translates into."""

from __future__ import annotations

from ccgan.media_range import K_PER_T63_S
from mjx_arm import domains
from tracking.config import require


def check_target_file(cfg) -> None:
    """target_domain_file: a readable Domain file (`read_target_file`), given instead of a
    target_domain (left at its default), for the chain (the rod has only its named media)."""
    if cfg.target_domain_file is None:
        return
    default = type(cfg).__dataclass_fields__["target_domain"].default
    require(
        cfg.target_domain == default,
        "target_domain_file",
        f"gives D_c instead of target_domain, which must stay {default!r} (got"
        f" {cfg.target_domain!r}): give one or the other",
    )
    require(
        cfg.simulator != "rod",
        "target_domain_file",
        "is a medium of the chain: the rod (simulator 'rod') has only its own named media"
        " (target_domain constrained or aged)",
    )
    try:
        read_target_file(cfg)
    except (OSError, ValueError) as err:
        require(False, "target_domain_file", f"is unusable: {err}")


def read_target_file(cfg):
    """The `mjx_arm.domains.DomainFile` of cfg.target_domain_file (its Domain named
    "identified"), or None without one.

    Raises:
      FileNotFoundError, ValueError: as `mjx_arm.domains.read_domain_file`.
    """
    if cfg.target_domain_file is None:
        return None
    return domains.read_domain_file(cfg.target_domain_file)


def target_file_record(target_file, arm_s, arm_c) -> dict:
    """shapes.json's {"target_domain_file": ...} ({} without a file): the file's record
    (`DomainFile.record`: path, sha256, identification method, every Domain field) and
    "values", the D_c arm's physical values (`mjx_arm.domains.physical_values`: viscosity over
    the source medium's, stiffness and mass factors), comparable with the built-in media's."""
    if target_file is None:
        return {}
    values = domains.physical_values(arm_c.mj_model, arm_s.mj_model, arm_c.domain)
    return {"target_domain_file": target_file.record() | {"values": values}}


def medium_note(method: str, medium: dict) -> str:
    """The note of a conditioned translator's medium (`eval.methods.medium_record`): the (r, s)
    it translates into, what that medium is to its range, and the k its rule holds."""
    span = medium["range"]
    role = {
        "training": "one of its training media",
        "held out": "one of its held-out media",
    }.get(medium["role"], "neither a training nor a held-out medium")
    return (
        f"{method.upper()}: translates into this run's D_c as drag ratio r ="
        f" {medium['drag_ratio']:.4g}, stiffness s = {medium['stiffness_scale']:.4g} (inside its"
        f" range r {span['drag_ratio']}, s {span['stiffness_scale']}; {role}), each command"
        f" held its rule's k = {medium['k']} (the grid's nearest to {K_PER_T63_S} x the fitted"
        f" 63% step time {medium['t63_s']:.1f} s)."
    )
