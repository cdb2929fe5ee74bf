"""Generate ``models/softarm.xml`` from one physical-parameter dataclass.

The arm is a chain of rigid capsule segments hanging from a fixed base. Each segment carries two
bending hinges, a twist hinge and a slide joint (stretch) at its top, with stiffness derived from
the rod's E, G, A, I over the segment length. Each chamber is a fixed tendon: its length is the
small-angle length of a fibre 20 mm off the axis (stretch plus offset times bend over every joint
the chamber spans), so a chamber force F puts the constant couple F r and the axial force F on
each spanned joint in its own frame: the internal load of a pressurised chamber, as in the
Cosserat reference. A positive actuator force lengthens the tendon, as a pressurised chamber
pushes its end caps apart.

Stiffness, chamber gain and the medium's drag carry the factors fitted to the reference rod by
``python -m mjx_arm.fit`` (stored in ``models/softarm_fit.json``).

Run ``python -m mjx_arm.model_gen`` to rewrite the committed model; ``--check`` only compares.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import numbers
import sys
from pathlib import Path

from mjx_arm import constants, fitted, run_folder
from mjx_arm import section as sections


@dataclasses.dataclass(frozen=True)
class ArmParams:
    """Physical and numerical parameters of the arm model.

    Sources: [paper] Kushawaha et al., "Domain Translation of a Soft Robotic Arm using Conditional
    Cycle GAN"; [code] the authors' public `utils/i_supportModelParam.py`; [fit] fitted to the
    reference Cosserat rod by `python -m mjx_arm.fit` (`models/softarm_fit.json`); [choice] a
    modelling choice explained inline.
    """

    section: str = "isupport"
    """What carries bending, twist and stretch (`mjx_arm.section`): "isupport", the three
    chamber tubes [SoRoMoX's I-Support model], or "solid", a solid disc of `radius_m` (the
    earlier, 15x stiffer model, kept as a comparison). The fitted factors below default to the
    section's own fit; `dataclasses.replace` keeps them, so build a new `ArmParams(section=...)`
    to change section."""
    length_m: float = 0.2
    """Arm length (m) [paper: ~0.202 m; code: 0.19 m]."""
    radius_m: float = 0.03
    """Outer radius of the arm (m) [paper, code]: the solid section's radius and the capsules'
    drawn size."""
    mass_kg: float = 0.183
    """Total mass (kg) [paper: 183 g], spread evenly along the length."""
    youngs_modulus_pa: float = 1.646439e6
    """Young's modulus E (Pa) [code]."""
    poisson_ratio: float = 0.5
    """Poisson ratio, so G = E / 3 [code]."""
    chamber_length_m: float = 0.18
    """Length of the pressure chambers from the base (m) [paper: ~180 mm]."""
    chamber_offset_m: float = 0.02
    """Chamber centre distance from the arm's axis (m) [paper, code]."""
    chamber_outer_radius_m: float = 0.00779
    """Chamber tube outer radius (m) [code]."""
    chamber_wall_m: float = 0.0014
    """Chamber tube wall thickness (m) [code]."""
    gravity_mps2: float = 9.80513
    """Gravity (m/s^2), the arm hangs along -z [code]."""
    n_segments: int = 10
    """Rigid segments in the chain [choice: the fidelity-vs-speed table of results/fidelity.md:
    20 and 30 segments are no closer to the rod and several times slower]."""
    timestep_s: float = 0.004
    """Physics timestep (s) [choice: stable with `Domain.inertia_scale` on full-range programs
    in both media, with the rod's 63% times kept (results/fidelity.md)]."""
    medium_drag_ns_per_m2: float | None = None
    """Viscous drag of the source domain's medium on the arm, force per unit length per unit
    speed (N s/m^2) [fit; the paper code's damper at 800 1/s and 2e-4 s is a drag of 867.6 1/s
    per unit mass, 794 N s/m^2 on 0.915 kg/m]. The MJCF's viscosity is derived from it per
    segment count. None: the section's fit."""
    stiffness_scale: float | None = None
    """Multiplies the bend, twist and stretch stiffness derived from E and G [fit]. None: the
    section's fit."""
    chamber_gain_scale: float | None = None
    """Multiplies the chamber force per bar, pressure x lumen area [fit]. None: the section's
    fit."""
    constrained_viscosity_scale: float | None = None
    """Viscosity of the constrained medium over the source's [fit to the reference's 8000 vs
    800 1/s at the paper's 2e-4 s step]. Written into the MJCF's `<custom>`, where
    `mjx_arm.domains.CONSTRAINED` reads it. None: the section's fit."""
    bend_armature_scale: float = 4.0
    """Joint armature of each ball joint, as a multiple of the segment's own rotational inertia
    about its top [choice: slows only the segment-local modes so explicit drag stays stable at
    `timestep_s`; the overdamped bending response is set by stiffness and drag, not inertia]."""
    stretch_armature_scale: float = 4.0
    """Slide-joint armature as a multiple of the segment mass [choice: as above, axial mode]."""
    alternate_bend: bool | None = None
    """Alternate the order of each segment's two bending hinges, x then y on even segments, y
    then x on odd ones [choice: two hinges in a row turn by Rx(a) Ry(b) = exp(a x + b y + ab/2 z
    + ...), a spurious twist of ab/2 per joint that accumulates along the arm and turns the
    bending plane of chambers 1 and 2 (`tests/test_model.py`); reversing the order flips its
    sign, so neighbours cancel it. A third hinge (x/2, y, x/2) cancels it in each segment too,
    but adds ten joints and slowed MJX's compile on the CPU]. None: on for the I-Support
    section, off for the solid one, whose frozen model keeps x then y throughout.
    """
    stretch_softening: bool | None = None
    """Bend every hinge the chamber span covers like the stretched rod, (c - k q) / e^3, with
    e read from the chamber pressures (`mjx_arm.stretch`) [choice: the paper's Cosserat law
    (Gazzola et al. 2018) softens bending as e^3 and the chambers stretch the body by up to
    37%; constant springs cannot follow it]. None: on for the I-Support section, off for the
    solid one, whose frozen model keeps constant springs."""
    euler_implicit_damping: bool = False
    """Keep MuJoCo's implicit joint-damping pass in the Euler step [choice: the joints carry no
    damping (the reference rod has no material damping; the medium does all of it), so the
    pass, an extra factorisation of the mass matrix every step, is switched off with
    `<flag eulerdamp="disable"/>`]."""

    def __post_init__(self):
        if self.section not in sections.SECTIONS:
            raise ValueError(f"unknown section {self.section!r}; known: {sections.SECTIONS}")
        if self.alternate_bend is None:
            object.__setattr__(self, "alternate_bend", self.section == "isupport")
        if self.stretch_softening is None:
            object.__setattr__(self, "stretch_softening", self.section == "isupport")
        missing = [n for n in fitted.FIT_NAMES if getattr(self, n) is None]
        if missing:
            stored = fitted.load_fit(fitted.FIT_PATHS[self.section])
            values = stored or fitted.unfitted(self.mass_kg / self.length_m)
            for name in missing:
                object.__setattr__(self, name, values[name])

    @property
    def cross_section(self) -> sections.Section:
        """Area, second moment and polar moment of the load-carrying section."""
        return sections.section(
            self.section,
            self.radius_m,
            self.chamber_outer_radius_m,
            self.chamber_wall_m,
            self.chamber_offset_m,
        )

    @property
    def drag_diameter_m(self) -> float:
        """Mean side of a segment's inertia box, the diameter in MuJoCo's Stokes drag.

        A body whose inertia is the segment's (`segment_inertia_kgm2`) has a box of sides
        2 sqrt(3) g, 2 sqrt(3) g and l, g the section's radius of gyration (sqrt(3) r for a
        solid disc).
        """
        side = 2.0 * math.sqrt(3.0) * self.cross_section.gyration_radius_m
        return (2.0 * side + self.segment_length_m) / 3.0

    @property
    def viscosity_pa_s(self) -> float:
        """MJCF viscosity giving each segment the drag 3 pi mu d = medium_drag * l.

        MuJoCo's inertia-box drag on a body grows with its box's mean side, not its length, so a
        fixed viscosity would damp a 20-segment arm almost twice as much as a 10-segment one.
        """
        drag_per_segment = self.medium_drag_ns_per_m2 * self.segment_length_m
        return drag_per_segment / (3.0 * math.pi * self.drag_diameter_m)

    @property
    def segment_length_m(self) -> float:
        return self.length_m / self.n_segments

    @property
    def segment_mass_kg(self) -> float:
        return self.mass_kg / self.n_segments

    @property
    def shear_modulus_pa(self) -> float:
        return self.youngs_modulus_pa / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def area_m2(self) -> float:
        return self.cross_section.area_m2

    @property
    def second_moment_m4(self) -> float:
        return self.cross_section.second_moment_m4

    @property
    def polar_moment_m4(self) -> float:
        return self.cross_section.polar_moment_m4

    @property
    def bend_stiffness_nm_per_rad(self) -> float:
        """s E I / l (s = stiffness_scale): one joint stands for one segment length of rod."""
        e_i = self.youngs_modulus_pa * self.second_moment_m4
        return self.stiffness_scale * e_i / self.segment_length_m

    @property
    def twist_stiffness_nm_per_rad(self) -> float:
        """s G J / l."""
        g_j = self.shear_modulus_pa * self.polar_moment_m4
        return self.stiffness_scale * g_j / self.segment_length_m

    @property
    def stretch_stiffness_n_per_m(self) -> float:
        """s E A / l."""
        return self.stiffness_scale * self.youngs_modulus_pa * self.area_m2 / self.segment_length_m

    @property
    def chamber_gain_n_per_bar(self) -> float:
        """Chamber force per bar: gain scale x lumen area x 1e5 Pa/bar."""
        return self.chamber_gain_scale * self.chamber_area_m2 * constants.BAR_TO_PA

    @property
    def chamber_area_m2(self) -> float:
        """Effective area: the chamber lumen, on which pressure pushes the end cap."""
        inner = self.chamber_outer_radius_m - self.chamber_wall_m
        return math.pi * inner**2

    @property
    def stretch_per_bar(self) -> float:
        """Axial rest strain of the chamber span per bar of summed chamber pressure (1/bar): the
        chain's own chamber force per bar over its stretch stiffness s E A."""
        axial = self.stiffness_scale * self.youngs_modulus_pa * self.area_m2
        return self.chamber_gain_n_per_bar / axial

    @property
    def segment_inertia_kgm2(self) -> tuple[float, float, float]:
        """Inertia of one segment about its centre of mass (x, y, z), its mass spread like the
        section's area: m (I / A + l^2 / 12) across, m J / A about the axis."""
        m, l, sec = self.segment_mass_kg, self.segment_length_m, self.cross_section
        transverse = m * (sec.second_moment_m4 / sec.area_m2 + l**2 / 12.0)
        return (transverse, transverse, m * sec.polar_moment_m4 / sec.area_m2)

    @property
    def bend_armature_kgm2(self) -> float:
        transverse = self.segment_inertia_kgm2[0]
        about_top = transverse + self.segment_mass_kg * (self.segment_length_m / 2.0) ** 2
        return self.bend_armature_scale * about_top

    @property
    def stretch_armature_kg(self) -> float:
        return self.stretch_armature_scale * self.segment_mass_kg

    def validate(self) -> None:
        """Raises ValueError for parameters that cannot make a model (TypeError for an
        n_segments that is not a whole number, e.g. 10.5)."""
        if isinstance(self.n_segments, bool) or not isinstance(self.n_segments, numbers.Integral):
            raise TypeError(
                f"n_segments must be an int >= 2 (rigid segments in the chain), got"
                f" {self.n_segments!r} of type {type(self.n_segments).__name__}"
            )
        if self.n_segments < 2:
            raise ValueError(f"n_segments must be >= 2, got {self.n_segments}")
        if not 0.0 < self.chamber_length_m <= self.length_m:
            raise ValueError("chamber_length_m must lie in (0, length_m]")
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"{field.name} must be finite, got {value}")
        positive = ("length_m", "radius_m", "mass_kg", "youngs_modulus_pa", "timestep_s")
        fitted = (
            "medium_drag_ns_per_m2",
            "stiffness_scale",
            "chamber_gain_scale",
            "constrained_viscosity_scale",
        )
        for name in positive + fitted:
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be > 0 (a zero viscosity drops MJX's fluid code)")


#: How the MJCF header describes each section.
SECTION_TEXT = {
    "isupport": "the three chamber tubes carry the loads [SoRoMoX],\n"
    "    joined by their caps: A = 3 A_t, I = 3 pi/4 (r_o^4 - r_i^4) + 3/2 A_t d^2, J = 2 I;",
    "solid": "a solid disc of the arm's radius: A = pi r^2, I = pi r^4 / 4, J = 2 I;",
}


def _f(x: float) -> str:
    """Formats a number compactly and reproducibly."""
    return f"{x:.6g}"


def chamber_span_weights(params: ArmParams) -> list[tuple[int, float, float]]:
    """How much of each joint's rod the chamber covers, as (segment, stretch, bend) fractions.

    A slide joint stands for its own segment [i l, (i + 1) l]; the bending hinges at the top of
    segment i stand for the rod around them, [i l - l/2, i l + l/2] (the base ones for
    [0, l/2], hence their doubled stiffness). A chamber of length L_c adds its couple and
    force in proportion to the overlap with [0, L_c], so the lumped chain bends and stretches by
    exactly F r L_c / (E I) and F L_c / (E A) for any segment count. Only joints with a nonzero
    fraction are listed.
    """
    seg, span = params.segment_length_m, params.chamber_length_m

    def overlap(lo: float, hi: float) -> float:
        return max(0.0, min(hi, span) - max(lo, 0.0)) / (hi - max(lo, 0.0))

    weights = []
    for i in range(params.n_segments):
        stretch = overlap(i * seg, (i + 1) * seg)
        bend = overlap(i * seg - seg / 2, i * seg + seg / 2)
        if stretch > 1e-9 or bend > 1e-9:
            weights.append((i, stretch, bend))
    return weights


def bend_hinges(params: ArmParams, segment: int) -> list[tuple[str, str]]:
    """The bending hinges at the top of `segment`, in order: (name suffix, axis)."""
    hinges = [("x", "1 0 0"), ("y", "0 1 0")]
    return hinges[::-1] if params.alternate_bend and segment % 2 else hinges


def softened_hinges(params: ArmParams) -> list[tuple[str, float, float]]:
    """The bending hinges `mjx_arm.stretch` softens: (joint name, stiffness N m/rad, share of
    its rod inside the chamber span), for every hinge the span covers."""
    hinges = []
    for i, _, bend in chamber_span_weights(params):
        if bend <= 1e-9:
            continue
        stiffness = (2.0 if i == 0 else 1.0) * params.bend_stiffness_nm_per_rad
        for axis, _ in bend_hinges(params, i):
            hinges.append((f"bend_{i}_{axis}", stiffness, bend))
    return hinges


def chamber_offsets_m(params: ArmParams) -> list[tuple[float, float]]:
    """(x, y) of each chamber's centre in a segment's frame (m), at 0, 120, 240 degrees."""
    angles = [2.0 * math.pi * k / 3.0 for k in range(3)]
    return [
        (params.chamber_offset_m * math.cos(a), params.chamber_offset_m * math.sin(a))
        for a in angles
    ]


def _header(p: ArmParams) -> str:
    """The MJCF's leading comment: every number with its source."""
    seg = p.segment_length_m
    sec = p.cross_section
    section_text = SECTION_TEXT[p.section]
    bend_text = (
        "x then y on even segments, y then x on odd ones (no accumulated twist);"
        if p.alternate_bend
        else "x then y;"
    )
    softening = (
        "  Stretch softening [choice, the paper's Cosserat law]: on every bending hinge the\n"
        "    chambers span, soften_<joint> (gain affine in the angle) and unload_<joint> (motor)\n"
        "    make the torque (chamber couple - k q) / e^3, e = 1 + w s (p0 + p1 + p2) with\n"
        f"    s = {_f(p.stretch_per_bar)} 1/bar (<custom> stretch_per_bar) and w the actuator's\n"
        "    user value; mjx_arm.stretch sets their controls from the valve pressures.\n"
        if p.stretch_softening
        else ""
    )
    header = f"""<!--
  Soft pneumatic arm (I-Support module) as a chain of {p.n_segments} rigid segments.
  GENERATED by `python -m mjx_arm.model_gen` from mjx_arm.model_gen.ArmParams: do not edit by hand.

  Sources: [paper] Kushawaha et al., Domain Translation of a Soft Robotic Arm using CCGAN;
  [code] the authors' utils/i_supportModelParam.py; [fit] `python -m mjx_arm.fit` against the
  reference Cosserat rod (models/softarm_fit.json); [choice] see ArmParams.
    length {_f(p.length_m)} m [paper ~0.202, code 0.19], radius {_f(p.radius_m)} m [paper, code],
    mass {_f(p.mass_kg)} kg [paper 183 g], E {_f(p.youngs_modulus_pa)} Pa [code],
    Poisson {_f(p.poisson_ratio)} so G = {_f(p.shear_modulus_pa)} Pa [code],
    gravity {_f(p.gravity_mps2)} m/s^2 [code].
  Section "{p.section}" (mjx_arm.section): {section_text}
    A = {_f(sec.area_m2)} m^2, I = {_f(sec.second_moment_m4)} m^4,
    J = {_f(sec.polar_moment_m4)} m^4.
  Per segment (l = {_f(seg)} m, m = {_f(p.segment_mass_kg)} kg spread like the section's area),
  stiffness scaled by {_f(p.stiffness_scale)} [fit]:
    bending hinges s*E*I/l = {_f(p.bend_stiffness_nm_per_rad)} N m/rad,
      {bend_text}
    twist hinge (z) s*G*J/l = {_f(p.twist_stiffness_nm_per_rad)} N m/rad;
      the base joints stand for the half segment at the clamp, so twice these: this places each
      joint's compliance at the centroid of the rod it lumps and makes the tip deflection under
      a uniform moment exact for any segment count [choice];
    slide-joint stiffness s*E*A/l = {_f(p.stretch_stiffness_n_per_m)} N/m;
    armature: hinges {_f(p.bend_armature_kgm2)} kg m^2, slide {_f(p.stretch_armature_kg)} kg
      [choice, see ArmParams]; no joint damping: the medium damps the arm.
  Chambers: 3 fixed tendons, {_f(p.chamber_offset_m)} m off the axis at 0/120/240 deg
    [paper, code], spanning {_f(p.chamber_length_m)} m from the base [paper] (each joint
    weighted by the share of its rod inside the span, see chamber_span_weights);
    force = pressure x lumen area pi (r_out - wall)^2 = {_f(p.chamber_area_m2)} m^2
    [code geometry] x {_f(p.chamber_gain_scale)} [fit],
    so gain {_f(p.chamber_gain_n_per_bar)} N/bar; ctrl is the chamber pressure in bar,
    0..{_f(constants.P_MAX_BAR)} [paper].
{softening}  Valves: first order toward the command, tau rise {_f(constants.VALVE_TAU_RISE_S)} s,
    drop {_f(constants.VALVE_TAU_DROP_S)} s, floor {_f(constants.P_MIN_BAR)} bar [paper, code].
    MuJoCo's filter dynamics has one time constant, so mjx_arm.valve applies the valve and
    these numbers travel in <custom>.
  Medium: drag {_f(p.medium_drag_ns_per_m2)} N s/m^2 per length [fit], so viscosity
    {_f(p.viscosity_pa_s)} Pa s on these segments, for the source domain; the constrained
    domain scales it by {_f(p.constrained_viscosity_scale)} [fit to the paper's 10x per-mass
    damping].
    Integrator Euler (MJX has no implicitfast with fluid drag), timestep {_f(p.timestep_s)} s
    [choice], dense Jacobians, contacts off (the arm touches nothing).
-->
"""
    return header


def _segment_lines(p: ArmParams) -> list[str]:
    """The nested segment bodies with their joints, inertia, capsule and (last) the tip site."""
    seg = p.segment_length_m
    inertia = p.segment_inertia_kgm2
    lines = []
    indent = "    "
    for i in range(p.n_segments):
        pos = "0 0 0" if i == 0 else f"0 0 {_f(-seg)}"
        lines.append(f'{indent}<body name="seg_{i}" pos="{pos}" childclass="segment">')
        inner = indent + "  "
        base = i == 0
        bend = (2.0 if base else 1.0) * p.bend_stiffness_nm_per_rad  # the clamp's half segment
        twist = _f((2.0 if base else 1.0) * p.twist_stiffness_nm_per_rad)
        for axis, vector in bend_hinges(p, i):
            stiff = f' stiffness="{_f(bend)}"' if base else ""
            lines.append(
                f'{inner}<joint name="bend_{i}_{axis}" class="bend" axis="{vector}"{stiff}/>'
            )
        lines.append(
            f'{inner}<joint name="twist_{i}" class="bend" axis="0 0 1" stiffness="{twist}"/>'
        )
        lines.append(f'{inner}<joint name="stretch_{i}" class="stretch"/>')
        lines.append(
            f'{inner}<inertial pos="0 0 {_f(-seg / 2)}" mass="{_f(p.segment_mass_kg)}"'
            f' diaginertia="{_f(inertia[0])} {_f(inertia[1])} {_f(inertia[2])}"/>'
        )
        lines.append(f'{inner}<geom name="seg_{i}" fromto="0 0 0 0 0 {_f(-seg)}"/>')
        if i == p.n_segments - 1:
            # quat (0 1 0 0) turns the site half a turn about x, so its z axis points down the arm.
            lines.append(
                f'{inner}<site name="{constants.TIP_SITE}" pos="0 0 {_f(-seg)}" quat="0 1 0 0"'
                ' size="0.004" rgba="0.9 0.1 0.1 1"/>'
            )
        indent = inner
    for _ in range(p.n_segments):
        indent = indent[:-2]
        lines.append(f"{indent}</body>")
    lines.append("  </worldbody>")

    return lines


def _tendon_lines(p: ArmParams) -> list[str]:
    """One fixed tendon per chamber: a fibre's length over the joints the chamber spans."""
    offsets = chamber_offsets_m(p)
    weights = chamber_span_weights(p)
    lines = []
    # A fibre at (x, y) lengthens by q_stretch - y q_bend_x + x q_bend_y over one joint.
    lines.append("  <tendon>")
    for k, (x, y) in enumerate(offsets):
        lines.append(f'    <fixed name="chamber_{k}">')
        for i, stretch, bend in weights:
            fibre = {"x": -y * bend, "y": x * bend}
            terms = [("stretch", stretch)] + [
                (f"bend_{{i}}_{axis}", fibre[axis]) for axis, _ in bend_hinges(p, i)
            ]
            for joint, coef in terms:
                if abs(coef) > 1e-12:
                    name = f"stretch_{i}" if joint == "stretch" else joint.format(i=i)
                    lines.append(f'      <joint joint="{name}" coef="{_f(coef)}"/>')
        lines.append("    </fixed>")
    lines.append("  </tendon>")

    return lines


def generate_xml(params: ArmParams = ArmParams()) -> str:
    """Returns the MJCF text of the arm described by `params`."""
    params.validate()
    p = params
    header = _header(p)
    lines = [header.rstrip("\n"), '<mujoco model="softarm">']
    lines.append('  <compiler angle="radian" autolimits="true"/>')
    lines.append(
        f'  <option timestep="{_f(p.timestep_s)}" integrator="Euler" jacobian="dense"'
        f' gravity="0 0 {_f(-p.gravity_mps2)}" viscosity="{_f(p.viscosity_pa_s)}" density="0">'
    )
    euler_damp = "" if p.euler_implicit_damping else ' eulerdamp="disable"'
    lines.append(f'    <flag contact="disable"{euler_damp}/>')
    lines.append("  </option>")
    if p.stretch_softening:
        lines.append('  <size nuser_actuator="1"/>')
    lines.append("  <custom>")
    for name, value in constants.CUSTOM_VALVE_FIELDS.items():
        lines.append(f'    <numeric name="{name}" data="{_f(value)}"/>')
    lines.append(
        f'    <numeric name="{constants.CUSTOM_CONSTRAINED_SCALE}"'
        f' data="{_f(p.constrained_viscosity_scale)}"/>'
    )
    if p.stretch_softening:
        lines.append(
            f'    <numeric name="{constants.CUSTOM_STRETCH_PER_BAR}"'
            f' data="{_f(p.stretch_per_bar)}"/>'
        )
    lines.append("  </custom>")
    lines.append("  <visual>")
    lines.append('    <global offwidth="1280" offheight="720"/>')
    lines.append("  </visual>")
    lines.append("  <default>")
    lines.append('    <default class="segment">')
    lines.append(
        f'      <geom type="capsule" size="{_f(p.radius_m)}" contype="0" conaffinity="0"'
        ' rgba="0.85 0.55 0.35 1"/>'
    )
    lines.append('      <default class="bend">')
    lines.append(
        f'        <joint type="hinge" stiffness="{_f(p.bend_stiffness_nm_per_rad)}"'
        f' armature="{_f(p.bend_armature_kgm2)}"/>'
    )
    lines.append("      </default>")
    lines.append('      <default class="stretch">')
    lines.append(
        f'        <joint type="slide" axis="0 0 -1" stiffness="{_f(p.stretch_stiffness_n_per_m)}"'
        f' armature="{_f(p.stretch_armature_kg)}"/>'
    )
    lines.append("      </default>")
    lines.append("    </default>")
    lines.append('    <default class="chamber">')
    lines.append(
        f'      <general gainprm="{_f(p.chamber_gain_n_per_bar)}"'
        f' ctrlrange="0 {_f(constants.P_MAX_BAR)}" dyntype="none" biastype="none"/>'
    )
    lines.append("    </default>")
    lines.append("  </default>")
    lines.append("  <worldbody>")
    lines.append('    <light pos="0 -0.6 0.4" dir="0 1 -0.6" directional="true"/>')
    lines.append(
        '    <geom name="mount" type="box" size="0.05 0.05 0.005" pos="0 0 0.005"'
        ' contype="0" conaffinity="0" rgba="0.3 0.3 0.3 1"/>'
    )

    lines += _segment_lines(p)
    lines += _tendon_lines(p)
    lines.append("  <actuator>")
    for name in constants.CHAMBER_ACTUATORS:
        lines.append(f'    <general name="{name}" tendon="{name}" class="chamber"/>')
    if p.stretch_softening:
        for joint, stiffness, weight in softened_hinges(p):
            lines.append(
                f'    <general name="{constants.SOFTEN_PREFIX}{joint}" joint="{joint}"'
                f' gaintype="affine" gainprm="0 {_f(stiffness)} 0" biastype="none"'
                f' user="{_f(weight)}"/>'
            )
            lines.append(
                f'    <motor name="{constants.UNLOAD_PREFIX}{joint}" joint="{joint}"'
                f' user="{_f(weight)}"/>'
            )
    lines.append("  </actuator>")

    lines.append("  <sensor>")
    lines.append(f'    <framepos name="tip_pos" objtype="site" objname="{constants.TIP_SITE}"/>')
    lines.append(f'    <framezaxis name="tip_d3" objtype="site" objname="{constants.TIP_SITE}"/>')
    lines.append("  </sensor>")
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m mjx_arm.model_gen",
        description=__doc__.splitlines()[0].rstrip(".")
        + ". By default it rewrites the committed models/softarm.xml, and nothing else.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "--out", type=Path, default=constants.DEFAULT_MODEL_PATH, help="the MJCF file to write"
    )
    parser.add_argument(
        "--segments", type=int, default=None, help="override n_segments (default: ArmParams')"
    )
    parser.add_argument(
        "--section", choices=sections.SECTIONS, default="isupport", help="the body's cross-section"
    )
    parser.add_argument("--check", action="store_true", help="only compare with --out")
    args = parser.parse_args(argv)
    if args.segments is not None and args.segments < 2:
        parser.error("--segments must be >= 2")
    if not args.check:
        run_folder.check_out(parser, "--out", args.out, file=True)
    elif args.out.is_dir():
        parser.error(f"--out {args.out} is a folder, not a file")
    params = ArmParams(section=args.section)
    if args.segments is not None:
        params = dataclasses.replace(params, n_segments=args.segments)
    text = generate_xml(params)
    if args.check:
        same = args.out.exists() and args.out.read_text() == text
        print(f"{args.out}: {'up to date' if same else 'DIFFERS from the generator'}")
        return 0 if same else 1
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out} ({params.n_segments} segments)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
