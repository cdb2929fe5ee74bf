"""The markdown report of `mjx_arm.fidelity`'s results, one function per section."""

from __future__ import annotations

import math

from mjx_arm import fidelity_shapes, fitted


def _damper_drag_words(cosserat: dict) -> str:
    """What the reference rod's dampers (`cosserat["damping_per_s"]`, per domain, at its
    `timestep_s`) are as linear drags (`fitted.damper_drag_rate_per_s`), and their ratio beside
    the dampers' own: e.g. "a linear drag of 867.6 and 19,765 1/s per unit mass: the
    constrained medium is 22.8x the source's, not 10x"."""
    damping, dt_s = cosserat["damping_per_s"], cosserat["timestep_s"]
    source, constrained = (
        fitted.damper_drag_rate_per_s(damping[d], dt_s) for d in ("source", "constrained")
    )

    def rate(x: float) -> str:
        return f"{x:,.1f}" if x < 1000 else f"{x:,.0f}"

    ratio, nominal = constrained / source, damping["constrained"] / damping["source"]
    versus = (
        f"not {nominal:g}x" if abs(ratio / nominal - 1) > 0.005 else f"as the dampers' {nominal:g}x"
    )
    return (
        f"a linear drag of {rate(source)} and {rate(constrained)} 1/s per unit mass: the"
        f" constrained medium is {ratio:.1f}x the source's, {versus}"
    )


def _regime_lines(results: dict) -> list[str]:
    """The regime table: what the committed arm does, rod and chain, beside the solid disc."""
    rows = {(r["domain"], r["n_segments"]): r for r in results["rows"] if not r.get("variant")}
    src, con = rows[("source", 10)], rows[("constrained", 10)]
    solid = results.get("solid") or {}
    length = results["arm"]["length_m"]
    lines = [
        "| quantity | I-Support rod | chain, 10 segments | solid disc rod (earlier model) |",
        "|---|---|---|---|",
    ]
    for s in src["static"]:
        if s["chamber"] != 0:
            continue
        old = solid.get("rod_deflection_m", {}).get(str(s["pressure_bar"]))
        old = solid.get("rod_deflection_m", {}).get(s["pressure_bar"], old)
        lines.append(
            f"| chamber 0 at {s['pressure_bar']:g} bar: tip displacement mm / bend deg |"
            f" {1e3 * s['displacement_rod_m']:.1f} / {math.degrees(s['bend_rod_rad']):.1f} |"
            f" {1e3 * s['displacement_mujoco_m']:.1f} / {math.degrees(s['bend_mujoco_rad']):.1f} |"
            f" {'' if old is None else f'{1e3 * old:.1f} (xy) / -'} |"
        )
    common = next((s for s in src["static"] if s["chamber"] == -2), None)
    if common is not None:
        lines.append(
            "| chamber 0 at 3.5, others at 1.5 bar (common mode): bend deg |"
            f" {math.degrees(common['bend_rod_rad']):.1f} |"
            f" {math.degrees(common['bend_mujoco_rad']):.1f} | - |"
        )
    e = next(s for s in src["static"] if s["chamber"] == -1)
    lines.append(
        "| all three at 3.5 bar: elongation mm (% L) |"
        f" {1e3 * e['elongation_rod_m']:.1f} ({100 * e['elongation_rod_m'] / length:.0f}%) |"
        f" {1e3 * e['elongation_mujoco_m']:.1f}"
        f" ({100 * e['elongation_mujoco_m'] / length:.0f}%) | about 5 |"
    )
    for row in (src, con):
        w_rod, w_mj = row["babble"]["workspace_rod"], row["babble"]["workspace_mujoco"]
        old = solid.get("rod_babble_tip_rms_motion_m", {}).get(row["domain"])
        lines.append(
            f"| 60 s babbling, {row['domain']}: tip x / y range cm |"
            f" {100 * w_rod['x_range_m']:.1f} / {100 * w_rod['y_range_m']:.1f} |"
            f" {100 * w_mj['x_range_m']:.1f} / {100 * w_mj['y_range_m']:.1f} |"
            f" {'' if old is None else f'RMS excursion {1e3 * old:.1f} mm'} |"
        )
        lines.append(
            f"| 60 s babbling, {row['domain']}: orientation range / largest tilt rad |"
            f" {w_rod['orientation_range_rad']:.2f} / {w_rod['max_tilt_rad']:.2f} |"
            f" {w_mj['orientation_range_rad']:.2f} / {w_mj['max_tilt_rad']:.2f} | |"
        )
    for row in (src, con):
        t = row["t63_s"]
        old = solid.get("rod_t63_no_valve_s", {}).get(row["domain"])
        lines.append(
            f"| 63% time, {row['domain']}: no valve / with valve s |"
            f" {t['cosserat']['no_valve']:.2f} / {t['cosserat']['valve']:.2f} |"
            f" {t['mujoco']['no_valve']:.2f} / {t['mujoco']['valve']:.2f} |"
            f" {'' if old is None else f'{old:.2f} / -'} |"
        )
    return lines


def _limits_lines(results: dict) -> list[str]:
    """Which limits the committed model meets, per domain."""
    lines: list[str] = []
    lines += [
        "",
        "## Limits on held-out programs (committed model, 10 segments)",
        "",
        "| domain | tip RMS <= 3% L | tip RMS <= 10% of excursion | statics within 1% L |"
        " 63% times within 10% (worst) |",
        "|---|---|---|---|---|",
    ]
    for domain, v in results["verdict"].items():
        mark = {True: "yes", False: "NO"}
        lines.append(
            f"| {domain} | {mark[v['tip_rms_pct_length']]} | {mark[v['tip_rms_pct_excursion']]} |"
            f" {mark[v['static_error_pct_length']]} | {mark[v['t63_error_pct']]}"
            f" ({v['t63_error_pct_value']:.1f}%) |"
        )
    return lines


def _segment_lines(results: dict) -> list[str]:
    """Fidelity of each chain against the rod."""
    lines: list[str] = []
    lines += [
        "",
        "## Fidelity against segment count",
        "",
        "Static error: worst tip error over the eleven held commands. Babbling: 3 x 60 s, targets"
        f" uniform in [0.2, 3.5] bar held {results['protocol']['babble_hold_periods'][0]}-"
        f"{results['protocol']['babble_hold_periods'][1]} control periods; excursion is the rod's"
        " RMS tip distance from rest. MuJoCo C sim s/s: simulated seconds per wall second of"
        " these rollouts on this CPU (`mujoco.rollout`, one thread per trajectory); GPU"
        " throughput is in `bench/results/`.",
        "",
        "| model | domain | static error mm (% L) | tip RMS mm (% L) | % of excursion |"
        " tip max mm | d3 mean mrad | 63% error no valve / valve | MuJoCo C sim s/s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in results["rows"]:
        b, t = row["babble"], row["t63_s"]
        worst = max(row["static"], key=lambda s: s["tip_error_m"])
        err = {k: 100 * (t["mujoco"][k] / t["cosserat"][k] - 1) for k in ("no_valve", "valve")}
        lines.append(
            f"| {row['model']} | {row['domain']} | {1e3 * worst['tip_error_m']:.2f}"
            f" ({worst['tip_error_pct_length']:.2f}) | {1e3 * b['tip_rms_error_m']:.2f}"
            f" ({b['tip_rms_error_pct_length']:.2f}) | {b['tip_rms_error_pct_excursion']:.1f} |"
            f" {1e3 * b['tip_max_error_m']:.1f} | {1e3 * b['d3_mean_error_rad']:.1f} |"
            f" {err['no_valve']:+.1f}% / {err['valve']:+.1f}% |"
            f" {b['mujoco_c_sim_s_per_wall_s']:.0f} |"
        )
    return lines


def _stability_lines(results: dict) -> list[str]:
    """Full-range programs on MuJoCo C and MJX."""
    lines: list[str] = []
    p = results["protocol"]
    lines += [
        "",
        "## Stability at the committed timestep (10 segments, 4 ms)",
        "",
        f"{len(p['stability_seeds'])} programs of {p['babble_seconds']:g} s whose commands jump"
        " each chamber between 0 and 3.5 bar every"
        f" {p['stability_hold_periods'][0] / 10:g}-{p['stability_hold_periods'][1] / 10:g} s."
        " MuJoCo C runs all of them (a divergence raises); a stepped loop over the first counts"
        " MuJoCo's warnings; MJX on this machine's JAX backend runs the first, compared with C.",
        "",
        "| domain | finite | MuJoCo warnings | MJX vs C max tip mm | MJX vs C max d3 |"
        " tip xy range cm |",
        "|---|---|---|---|---|---|",
    ]
    for domain, s in results["stability"].items():
        lines.append(
            f"| {domain} | {s['finite']} | {s['mujoco_warnings'] or 'none'} |"
            f" {1e3 * s['mjx_vs_c_max_tip_m']:.1e} | {s['mjx_vs_c_max_d3']:.1e} |"
            f" {100 * s['tip_range_m']:.1f} |"
        )
    return lines


def _statics_lines(results: dict) -> list[str]:
    """Every held command of the source domain."""
    lines: list[str] = []
    lines += [
        "",
        "## Statics in detail (source; statics do not depend on the medium)",
        "",
        "| model | chamber | bar | tip error mm | % L | d3 error mrad | rod displacement mm |"
        " MuJoCo displacement mm |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in results["rows"]:
        if row["domain"] != "source":
            continue
        for s in row["static"]:
            chamber = {-1: "all", -2: "0, others 1.5"}.get(s["chamber"], s["chamber"])
            lines.append(
                f"| {row['model']} | {chamber} | {s['pressure_bar']:g} |"
                f" {1e3 * s['tip_error_m']:.2f} | {s['tip_error_pct_length']:.2f} |"
                f" {1e3 * s['d3_error_rad']:.1f} | {1e3 * s['displacement_rod_m']:.1f} |"
                f" {1e3 * s['displacement_mujoco_m']:.1f} |"
            )
    return lines


def to_markdown(results: dict) -> str:
    """A readable report of `run()`'s results."""
    length = results["arm"]["length_m"]
    c = results["cosserat"]
    a = results["arm"]
    lines = [
        "# The arm: regime and fidelity to the reference Cosserat rod",
        "",
        f"Produced by `{results['command']}` on {results['cpu']} ({results['cpu_cores']} cores)"
        f" in {results['wall_s']:.0f} s.",
        "",
        f'Arm: section "{a["section"]}" (`mjx_arm.section`), {a["length_m"]:g} m,'
        f" {a['mass_kg']:g} kg spread along the length, E = {a['youngs_modulus_pa'] / 1e6:.3f} MPa,"
        f" A = {a['area_m2']:.3g} m^2, I = {a['second_moment_m4']:.3g} m^4."
        f" Reference: `mjx_arm.cosserat` with the same section and mass, {c['n_elements']}"
        f" elements, {c.get('law', 'linear')} law"
        f"{' (force / e, couple / e^3, as PyElastica)' if c.get('law') == 'gazzola' else ''},"
        " the paper code's damper v <- v exp(-c dt) at c ="
        f" {c['damping_per_s']['source']:g} / {c['damping_per_s']['constrained']:g} 1/s and its"
        f" step of {c['timestep_s'] * 1e6:.0f} us ({_damper_drag_words(c)}). The committed model's"
        " media were fitted to this rod by `python -m mjx_arm.fit` on other programs; everything"
        " below is held out. The earlier solid-disc model's report is `results/fidelity_solid.md`.",
        "",
        "## Regime",
        "",
        "Held pressures (others at the 0.2 bar floor), settled; displacement is the tip's 3D"
        " distance from rest, bend the angle of d3 from its rest direction. Babbling: the three"
        f" held-out {results['protocol']['babble_seconds']:g} s programs below. The solid disc's"
        " numbers are its committed report's (xy deflection).",
        "",
    ]
    lines += _regime_lines(results)
    lines += _limits_lines(results)
    lines += _segment_lines(results)
    lines += _stability_lines(results)
    lines += _statics_lines(results)
    if results.get("shapes"):
        lines += fidelity_shapes.shapes_lines(results["shapes"])
    lines += ["", f"Arm length {length * 100:g} cm."]
    return "\n".join(lines) + "\n"
