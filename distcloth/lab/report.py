"""The lab's report: one Markdown section per test, values in the units a
textile lab uses next to SI."""
from __future__ import annotations

import math

from .cusick import CLAMP_RADIUS, PIXEL, SPECIMEN_RADIUS
from .kes_shear import kawabata_g
from .units import G_STANDARD as G
from .units import GF_CM2_PER_CM, GF_CM_PER_CM2


def _fmt(x: float, spec: str) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def peirce_section(r) -> str:
    if r.reason:
        return f"### Peirce cantilever\n\nnot measured: {r.reason}\n"
    # ASTM D1388 reports G = W c^3 in mg cm (W in mg/cm^2 = 100 kg/m^2, c in cm):
    # G [mg cm] = 1e8 rho c^3 = 1e8 G [N m] / g
    g_mg_cm = r.flexural_rigidity / G * 1e8
    return "\n".join([
        "### Peirce cantilever (ASTM D1388, option A)", "",
        "| quantity | simulated | from the material's B (exact elastica) |",
        "|---|---:|---:|",
        f"| overhang at 41.5° (cm) | {_fmt(100 * r.overhang, '.3f')} | "
        f"{_fmt(100 * r.exact_overhang, '.3f')} |",
        f"| bending length c = L/2 (cm) | {_fmt(50 * r.overhang, '.3f')} | "
        f"{_fmt(50 * r.exact_overhang, '.3f')} |",
        f"| flexural rigidity G = w c³ (µN·m; mg·cm) | {_fmt(1e6 * r.flexural_rigidity, '.3f')}; "
        f"{_fmt(g_mg_cm, '.1f')} | |",
        f"| bending stiffness B (µN·m) | {_fmt(1e6 * r.bending_from_elastica, '.3f')} | "
        f"{_fmt(1e6 * r.bending_input, '.3f')} |",
        "",
        f"B error {_fmt(100 * r.bending_error, '+.2f')} % (chord {_fmt(r.angle, '.3f')}° at "
        "that overhang: the search stops within 0.05°, about 0.1 % in B); mesh spacing "
        f"{_fmt(1e3 * r.spacing, '.2f')} mm, {r.evaluations} "
        f"overhang{'s' if r.evaluations != 1 else ''} tried, residual "
        f"{_fmt(r.residual, '.1e')} of a vertex weight, {r.wall:.1f} s.", ""])


def cusick_section(r) -> str:
    if r.reason and math.isnan(r.drape_coefficient):
        return f"### Cusick drape\n\nnot measured: {r.reason}\n"
    note = f" ({r.reason})" if r.reason else ""
    return "\n".join([
        "### Cusick drape (30 cm specimen on an 18 cm disc)", "",
        "| quantity | simulated |", "|---|---:|",
        f"| drape coefficient (%) | {_fmt(100 * r.drape_coefficient, '.1f')} |",
        f"| folds (nodes) | {r.nodes} |", "",
        f"{r.vertices} vertices (spacing {1e3 * r.spacing:.1f} mm), stop-and-go drape: "
        f"{r.iterations} iterations, residual {_fmt(r.residual, '.1e')}{note}, "
        f"{r.wall:.1f} s.", ""])


def tensile_section(results) -> str:
    out = ["### KES-FB1 tensile (20 cm × 5 cm, to 500 gf/cm)", "",
           "| direction | EMT (%) | EMT, material law: uniaxial … plane strain (%) | "
           "LT | WT (gf·cm/cm²) |", "|---|---:|---:|---:|---:|"]
    notes = []
    for r in results:
        lo, hi = r.law_emt
        out.append(f"| {r.direction} | {_fmt(100 * r.emt, '.3f')} | {_fmt(100 * lo, '.3f')} … "
                   f"{_fmt(100 * hi, '.3f')} | {_fmt(r.lt, '.3f')} | "
                   f"{_fmt(r.wt / GF_CM_PER_CM2, '.3f')} |")
        notes.append(f"{r.direction}: {len(r.strain) - 1} increments, {r.wall:.1f} s"
                     + (f" ({r.reason})" if r.reason else ""))
    return "\n".join(out + ["", "; ".join(notes) + ".", ""])


def _law_section(title: str, r, value, rows, increments: int) -> str:
    """A test with one characteristic value, simulated against the law."""
    if r.reason and math.isnan(value):
        return f"### {title}\n\nnot measured: {r.reason}\n"
    table = [f"| {name} | {_fmt(sim, spec)} | {_fmt(law, spec)} |" for name, sim, law, spec in rows]
    return "\n".join([f"### {title}", "", "| quantity | simulated | material law |",
                      "|---|---:|---:|", *table, "",
                      f"{increments} increments, {r.wall:.1f} s"
                      + (f" ({r.reason})" if r.reason else "") + ".", ""])


def shear_section(r) -> str:
    return _law_section("KES-FB1 shear (20 cm × 5 cm, to 8°)", r, r.g, [
        ("G (gf/cm/°)", kawabata_g(r.g), kawabata_g(r.g_law), ".4f"),
        ("G (N/m)", r.g, r.g_law, ".2f")], len(r.angle))


def bending_section(r) -> str:
    return _law_section("KES-FB2 pure bending (jaws 1 cm apart, to 2.5 /cm)", r, r.b, [
        ("B (gf·cm²/cm)", r.b / GF_CM2_PER_CM, r.b_law / GF_CM2_PER_CM, ".4f"),
        ("B (µN·m)", 1e6 * r.b, 1e6 * r.b_law, ".3f")], max(len(r.curvature) - 1, 0))


SECTIONS = {"tensile": tensile_section, "shear": shear_section, "bending": bending_section,
            "peirce": peirce_section, "cusick": cusick_section}


def cusick_picture(r, path: str) -> None:
    """The shadow seen from above, with the specimen's and the disc's circles."""
    # matplotlib only when a picture is drawn, without a display
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after use("Agg")
    half = 0.5 * r.shadow.shape[0] * PIXEL * 100
    fig, ax = plt.subplots(figsize=(4, 4), dpi=120)
    ax.imshow(r.shadow.T, origin="lower", extent=(-half, half, -half, half), cmap="Greys",
              vmin=0, vmax=1.6)
    for radius, style in ((SPECIMEN_RADIUS, "--"), (CLAMP_RADIUS, "-")):
        ax.add_patch(plt.Circle((0, 0), 100 * radius, fill=False, ls=style, color="tab:blue"))
    ax.set_xlabel("cm")
    ax.set_title(f"Cusick drape: DC {100 * r.drape_coefficient:.1f} %, {r.nodes} folds",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


PICTURES = {"cusick": cusick_picture}
