"""Names and fixed numbers that the MJCF model and the Python API share.

Every element that Python touches is named here once; a foreign MJCF must use the same names.
"""

from pathlib import Path

#: Repository root (the folder holding ``models/``).
ROOT = Path(__file__).resolve().parent.parent
#: The committed, generated arm model.
DEFAULT_MODEL_PATH = ROOT / "models" / "softarm.xml"
#: The earlier arm, whose body bent as a solid 30 mm disc (15x stiffer than the I-Support
#: section), kept byte for byte: the datasets and translators of results/solid/ were made with
#: it, and it is the comparison row of the model page. `ArmParams(section="solid")` regenerates its
#: physics.
SOLID_MODEL_PATH = ROOT / "models" / "softarm_solid.xml"
#: The previous I-Support arm, fitted to the reference rod without the stretch (dilatation)
#: factors of the paper's Cosserat law, kept byte for byte: its chain run, results/paper/run/
#: (babbling data, translators and tables), was made with it and is kept as history.
LINEAR_LAW_MODEL_PATH = ROOT / "models" / "softarm_linear.xml"
#: The arm the committed I-Support translators (results/paper/rerun_2026-11-27/run/) were
#: trained on by the chain's rerun, and so the default arm of every command that scores or
#: refines them (eval.shapes, the fine-tune stages).
TRANSLATOR_MODEL_PATH = DEFAULT_MODEL_PATH

#: Actuators of the three chambers, at 0, 120 and 240 degrees around the arm's axis.
CHAMBER_ACTUATORS = ("chamber_0", "chamber_1", "chamber_2")
#: Chambers, and the width of a pressure sample.
N_CHAMBERS = len(CHAMBER_ACTUATORS)
#: Width of a pose sample: tip position (m, 3) then the tip's unit tangent d3 (3).
POSE_DIM = 6
#: Site at the arm's free end; its z axis is the Cosserat d3 director (unit tangent).
TIP_SITE = "tip"

#: Control rate of the pressure programs (the paper's 10 Hz valves and sampling).
CONTROL_HZ = 10.0
CONTROL_PERIOD_S = 1.0 / CONTROL_HZ

#: Valve limits (bar, gauge). Commands saturate to [0, P_MAX]; chambers never vent below P_MIN.
P_MAX_BAR = 3.5
P_MIN_BAR = 0.2
#: First-order valve time constants (s): toward a higher command, toward a lower one.
VALVE_TAU_RISE_S = 0.2
VALVE_TAU_DROP_S = 0.56

#: Names of the <custom><numeric> fields that carry valve data inside an MJCF.
CUSTOM_VALVE_FIELDS = {
    "valve_tau_rise": VALVE_TAU_RISE_S,
    "valve_tau_drop": VALVE_TAU_DROP_S,
    "valve_p_min": P_MIN_BAR,
    "valve_p_max": P_MAX_BAR,
}

#: The <custom><numeric> field with the constrained medium's viscosity over the source's, which
#: `mjx_arm.fit` fits per model and `mjx_arm.domains.CONSTRAINED` applies.
CUSTOM_CONSTRAINED_SCALE = "constrained_viscosity_scale"

#: Actuators that make the chain's bending follow the rod's stretch (`mjx_arm.stretch`): on each
#: bending hinge the chamber span covers, "soften_<joint>" (gain affine in the joint angle)
#: and "unload_<joint>" (a motor). Models without them (the solid arm, the linear-law arm, a
#: foreign MJCF) bend with constant stiffness.
SOFTEN_PREFIX = "soften_"
UNLOAD_PREFIX = "unload_"
#: The <custom><numeric> field with the axial rest strain one bar of chamber pressure imposes
#: on the chamber span (1/bar): the stretch e = 1 + w * stretch_per_bar * (p0 + p1 + p2).
CUSTOM_STRETCH_PER_BAR = "stretch_per_bar"

BAR_TO_PA = 1.0e5

#: The paper code's media: translational damping constants c (1/s) of its damper
#: v <- v exp(-c dt), source and constrained, applied every `PAPER_TIMESTEP_S`.
PAPER_DAMPING_PER_S = {"source": 800.0, "constrained": 8000.0}
#: The paper code's simulator step (s) (PyElastica, position Verlet).
PAPER_TIMESTEP_S = 2e-4

#: A trajectory whose joint speed exceeds this (rad/s or m/s) is treated as diverged.
MAX_JOINT_SPEED = 1.0e3
