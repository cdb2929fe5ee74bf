"""`--simulator rod`: the five shapes scored in the reference Cosserat rod, the paper's own kind of
simulator, instead of the fitted chain.

With EvalConfig.simulator "rod" (`eval.pipeline.evaluate`):
  * the D_s targets [T, 6] are the rod's own D_s path: `mjx_arm.load_rod("source")` rollouts of
    the shape programs;
  * stretch only's k is chosen in the rod, by the same validation-program procedure
    (`tracking.held.choose_stretch_k` with rod arms: its candidates one padded batch on a GPU);
  * every method's D_c commands [T * k, 3] (bar) run in `load_rod(cfg.target_domain)`, float64,
    through `tracking.held.rollout_grouped` (on a GPU a few padded batches, each announced);
  * translators trained on the chain (their files record the chain MJCF's `Arm.model_hash`) and
    translators trained on the rod's own data (`RodArm.model_hash`, "rod-...") are both scored;
    the report says which arm each was trained on (`trained_on`); any other arm is refused;
  * the tracker plans in the chain's D_c arm (MuJoCo C, as in chain mode) towards the rod's
    targets at the rod's stretch k, and its commands run in the rod. Its resume cache
    (mpc_commands.npz) is fingerprinted by its targets, so a chain run's cache is never read as
    this one's (`tracking.mpc.track`);
  * the oracle (it optimises through MJX of the chain) and --render (videos draw the chain's
    MuJoCo model) are refused before any work (`check_simulator`), and so is --backend mjx
    (every rollout but the tracker's runs in the rod; the tracker plans in MuJoCo C).

The rod is latency-bound (`mjx_arm.rod_arm`): on the 2-core CPU about 25-37 simulated s per wall s
whatever the batch, on one H200 ~400 at batch 64 and ~1,090 at batch 512. So a full table (five
60 s shapes, k = 15, several methods and seeds) is a GPU job; on a CPU use short programs.
"""

from __future__ import annotations

import mjx_arm
from tracking.config import require

#: What scores the table: the fitted chain (MuJoCo C or MJX) or the reference rod.
SIMULATORS = ("chain", "rod")
#: The rod's floating-point type in the evaluation: the reference, to rounding.
ROD_DTYPE = "float64"
#: How shapes.md and shapes.json name each simulator.
SCORED_IN = {
    "chain": "the chain (the fitted MuJoCo arm)",
    "rod": "the reference rod (paper's law), float64",
}
#: What the report says of a translator by the arm its files record (`trained_on`).
CHAIN_TRAINED = "planned/trained in the chain, run in the rod"
ROD_TRAINED = "trained on the rod's data"
UNRECORDED = "its files record no arm"


def check_simulator(cfg) -> None:
    """Refuses, before any work, what the chosen simulator cannot do (`ConfigError`).

    Args:
      cfg: an `eval.pipeline.EvalConfig` (not imported: the pipeline imports this module).
    """
    require(
        cfg.simulator in SIMULATORS,
        "simulator",
        f"must be one of {list(SIMULATORS)}, got {cfg.simulator!r}",
    )
    if cfg.simulator != "rod":
        return
    require(
        "oracle" not in cfg.methods,
        "simulator",
        "rod: the oracle optimises through MJX of the chain and cannot be scored in the rod;"
        " leave oracle out of --methods",
    )
    require(
        not cfg.render,
        "simulator",
        "rod: --render is refused, as videos draw the chain's MuJoCo model; leave it out",
    )
    require(
        cfg.backend == "c",
        "simulator",
        "rod: --backend mjx is refused: every rollout runs in the rod, and the tracker plans in"
        " the chain's MuJoCo C",
    )


def load_rod_arms(target_domain: str) -> tuple[mjx_arm.RodArm, mjx_arm.RodArm]:
    """(the rod in "source", the rod in `target_domain`), float64."""
    return (
        mjx_arm.load_rod("source", dtype=ROD_DTYPE),
        mjx_arm.load_rod(target_domain, dtype=ROD_DTYPE),
    )


def trained_on(translators: dict, chain_hash: str, rod_hash: str) -> dict[str, str]:
    """{method: which arm its files record as trained on}, for the report: `CHAIN_TRAINED`,
    `ROD_TRAINED`, both joined when its seeds' files differ, or `UNRECORDED`.

    Args:
      translators: {method: `eval.methods.TranslatorMethod`} (already checked against both
        arms by `eval.methods.check_translator_arms`).
      chain_hash, rod_hash: the chain's `Arm.model_hash` and the rod's `RodArm.model_hash`.
    """
    out = {}
    for method, tr in translators.items():
        arms = [ROD_TRAINED if h == rod_hash else CHAIN_TRAINED for h in sorted(tr.model_hashes)]
        if chain_hash not in tr.model_hashes and rod_hash not in tr.model_hashes:
            arms = [UNRECORDED]
        out[method] = " and ".join(dict.fromkeys(arms))
    return out


def scored_in(results: dict) -> str | None:
    """The report's line saying which simulator scored the table (None for older files, which
    do not record it)."""
    simulator = results.get("simulator")
    if simulator is None:
        return None
    line = f"- scored in: {SCORED_IN.get(simulator, simulator)}"
    if simulator == "rod":
        rod = results.get("rod", {})
        line += (
            f" (`mjx_arm.load_rod`, model hash {rod.get('model_hash', '?')}): the D_s targets,"
            " stretch only's k and every method's D_c commands ran there"
        )
        if "mpc" in results.get("methods_run", ()):
            line += (
                "; the tracker planned in the chain (model hash"
                f" {rod.get('chain_model_hash', '?')}, MuJoCo C) towards the rod's targets"
            )
    return line


def rod_note(cfg, default_model: bool) -> str | None:
    """A note (shapes.md) on what ran in the chain with --simulator rod, or None: the tracker,
    and a chain other than the default model.

    Args:
      cfg: the `eval.pipeline.EvalConfig` run.
      default_model: whether the chain is the default I-Support model, whose physical values
        (`mjx_arm.ArmParams()`) the rod has.
    """
    parts = []
    if "mpc" in cfg.methods:
        parts.append(
            "the tracker planned in the chain's D_c arm (MuJoCo C) towards the rod's targets at"
            " the rod's stretch k, and its commands ran in the rod"
        )
    if not default_model:
        parts.append(
            "the rod has the default I-Support arm's physical values (mjx_arm.ArmParams()),"
            " which the chain given need not share"
        )
    if not parts:
        return None
    text = "; ".join(parts)
    return text[0].upper() + text[1:] + "."


def rod_description(plan) -> dict:
    """shapes.json's "rod": the rod that scored the table, the chain the tracker planned in,
    and the arm each translator was trained on (`trained_on`; plan: `eval.pipeline.Plan`)."""
    chain_hash = plan.tracker_arm.model_hash
    return {
        "scored_in": SCORED_IN["rod"],
        "model_hash": plan.arm_c.model_hash,
        "dtype": plan.arm_c.dtype,
        "chain_model_hash": chain_hash,
        "translators_trained_on": trained_on(plan.translators, chain_hash, plan.arm_c.model_hash),
    }
