"""Cross-sections of the arm's body: what carries bending, twist and stretch.

Two sections are modelled:

* ``"isupport"`` (the default): the I-Support module's three pneumatic chamber tubes carry the
  loads, as SoRoMoX's I-Support model takes them (`soromox`, `systems/pcs/isupport.py`: tubes of
  outer radius 7.79 mm and wall 1.4 mm, centres 20 mm off the axis). The tubes are joined by
  their end caps, so they bend about the arm's axis as one section (parallel-axis terms):

      A = 3 A_t,                     A_t = pi (r_o^2 - r_i^2)
      I = 3 pi/4 (r_o^4 - r_i^4) + A_t sum_k y_k^2 = 3 pi/4 (r_o^4 - r_i^4) + 3/2 A_t d^2
      J = I_xx + I_yy = 2 I          (perpendicular axes; the caps make the tubes twist together)

  with r_i = r_o - wall, d the tubes' distance from the axis, y_k = d sin(2 pi k / 3), and
  sum_k y_k^2 = sum_k x_k^2 = 3 d^2 / 2 for three tubes 120 degrees apart.
* ``"solid"``: a solid disc of the arm's radius, A = pi r^2, I = pi r^4 / 4, J = 2 I. This is the
  earlier model (about 15 times stiffer in bending); it stays as a named comparison.

The mass is not derived from the section: the arm's measured mass (tubes, caps, fittings) is
spread along its length, and the section only sets how it is distributed about the axis (the
radius of gyration sqrt(I / A)), which the segment inertias use.
"""

from __future__ import annotations

import math
from typing import NamedTuple

#: Names of the modelled cross-sections.
SECTIONS = ("isupport", "solid")


class Section(NamedTuple):
    """Geometric properties of a cross-section.

    Attributes:
      area_m2: load-carrying area A (m^2), for E A (stretch) and a G A (shear).
      second_moment_m4: second moment of area I about a bending axis through the arm's axis
        (m^4); the section is symmetric enough (three-fold) that every bending axis has the same.
      polar_moment_m4: polar second moment J about the arm's axis (m^4), for G J (twist).
    """

    area_m2: float
    second_moment_m4: float
    polar_moment_m4: float

    @property
    def gyration_radius_m(self) -> float:
        """sqrt(I / A) (m): with the mass spread like the area, the rotational inertia per unit
        mass about a bending axis is its square (r / 2 for a solid disc)."""
        return math.sqrt(self.second_moment_m4 / self.area_m2)


def solid_disc(radius_m: float) -> Section:
    """A solid disc of radius `radius_m` (m)."""
    second = math.pi * radius_m**4 / 4.0
    return Section(math.pi * radius_m**2, second, 2.0 * second)


def three_tubes(outer_radius_m: float, wall_m: float, offset_m: float) -> Section:
    """Three equal tubes (outer radius, wall, m) with centres `offset_m` off the axis, 120
    degrees apart, joined so they bend and twist as one section."""
    inner = outer_radius_m - wall_m
    if not 0.0 < inner < outer_radius_m:
        raise ValueError(f"tube wall {wall_m} m must lie in (0, outer radius {outer_radius_m} m)")
    tube_area = math.pi * (outer_radius_m**2 - inner**2)
    own = math.pi / 4.0 * (outer_radius_m**4 - inner**4)
    second = 3.0 * own + tube_area * 1.5 * offset_m**2
    return Section(3.0 * tube_area, second, 2.0 * second)


def section(
    name: str, radius_m: float, tube_outer_radius_m: float, tube_wall_m: float, offset_m: float
) -> Section:
    """The section `name` ("isupport" or "solid") of an arm with these dimensions (m)."""
    if name == "isupport":
        return three_tubes(tube_outer_radius_m, tube_wall_m, offset_m)
    if name == "solid":
        return solid_disc(radius_m)
    raise ValueError(f"unknown section {name!r}; known: {SECTIONS}")
