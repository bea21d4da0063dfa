"""The accuracy study's outputs from its rows: CSV, Markdown findings in
sentences, PNG plots (matplotlib, Agg).  Rank 0 only; no MPI, no simulation.

A row is a dict: ``name``, ``role``, ``status``, ``label``, ``settings``
(dict axis -> value text), ``wall``, ``stages`` (dict stage -> s),
the scalar metrics of ``metrics.compare`` and, for plots, ``times``/``rms``.
"""
from __future__ import annotations

import csv
import math
import os

import numpy as np

from .metrics import DRAPE_MEASURES, SCALAR_METRICS

DRAPE_UNITS = {"shadow_area": "m²", "drape_coefficient": "", "com_height": "m", "vertical_extent": "m"}
DRAPE_NAMES = {"shadow_area": "shadow area", "drape_coefficient": "drape coefficient",
               "com_height": "centre-of-mass height", "vertical_extent": "vertical extent"}


def chaos(noise, divergence: float, *, forced: bool = False) -> dict:
    """Is the scene chaotic?  The predictability horizon is the time at which the
    noise-floor rerun (the reference from positions moved ~1e-9 m) departs from the
    reference by more than ``divergence`` (RMS, m); a scene whose horizon falls inside
    the run is chaotic whether or not ``--chaotic`` said so (``auto``)."""
    horizon = noise.get("time_to_divergence", math.nan) if noise else math.nan
    diverged = math.isfinite(horizon)
    return {"chaotic": forced or diverged, "forced": forced, "auto": diverged and not forced,
            "horizon": horizon, "divergence": divergence,
            "noise_rms_max": noise.get("rms_max", math.nan) if noise else math.nan}


def ranking_metric(chaotic: bool) -> str:
    """What the Pareto front ranks by: positions, or for a chaotic scene (positions
    decorrelate) the centre-of-mass path."""
    return "com_max_error" if chaotic else "rms_mean"


def pareto(rows, cost="wall", error="rms_mean") -> list[int]:
    """Indices of the rows no other row beats in both cost and error (ties kept),
    sorted by cost."""
    ok = [i for i, r in enumerate(rows) if math.isfinite(r.get(cost, math.nan))
          and math.isfinite(r.get(error, math.nan))]
    front = []
    for i in ok:
        ci, ei = rows[i][cost], rows[i][error]
        if not any(rows[j][cost] <= ci and rows[j][error] <= ei
                   and (rows[j][cost] < ci or rows[j][error] < ei) for j in ok):
            front.append(i)
    return sorted(front, key=lambda i: rows[i][cost])


def write_csv(path: str, rows, axes, stages) -> None:
    cols = (["name", "role", "status"] + list(axes) + ["wall_s"] + [f"stage_{s}_s" for s in stages]
            + ["ksp_iterations_mean", "pareto"] + list(SCALAR_METRICS) + ["message"])
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for r in rows:
            w.writerow([r["name"], r["role"], r["status"]]
                       + [r["settings"].get(a, "") for a in axes]
                       + [_num(r.get("wall"))] + [_num(r["stages"].get(s)) for s in stages]
                       + [_num(r.get("ksp_iterations_mean")), int(bool(r.get("pareto")))]
                       + [_num(r.get(m)) for m in SCALAR_METRICS] + [r.get("message", "")])


def _num(v):
    if v is None:
        return ""
    return repr(float(v)) if isinstance(v, (float, np.floating)) else v


def _g(v, unit=""):
    if v is None or not math.isfinite(v):
        return "n/a" if v is None or math.isnan(v) else ("never" if v > 0 else "-inf")
    return f"{v:.3g}{unit}"


def _others(settings: dict, axis: str) -> tuple:
    return tuple(sorted((k, v) for k, v in settings.items() if k != axis))


# errors within this factor of the noise floor are not resolved differences
NOISE_FACTOR = 10


def _change(a: dict, b: dict, error: str, what: str, floor: float = math.nan) -> str:
    """How the error went from a to b, with what a chaotic ranking also needs (the
    final shadow area's distance from the reference's) and whether it is resolved."""
    ea, eb = a[error], b[error]
    if ea > 0 and eb > 0 and abs(ea / eb - 1) < 0.005:
        text = f"left the {what} unchanged to 3 digits ({_g(eb, ' m')})"
    elif eb > 0 and ea > eb:
        text = f"cut the {what} {ea / eb:.3g}× ({_g(ea, ' m')} → {_g(eb, ' m')})"
    elif ea > 0 and eb > ea:
        text = f"raised the {what} {eb / ea:.3g}× ({_g(ea, ' m')} → {_g(eb, ' m')})"
    else:
        text = f"left the {what} at {_g(eb, ' m')}"
    if error != "rms_mean" and "shadow_area_final_diff" in a and "shadow_area_final_diff" in b:
        text += (f"; the final shadow area's difference from the reference went from "
                 f"{_g(a['shadow_area_final_diff'], ' m²')} to {_g(b['shadow_area_final_diff'], ' m²')}")
    if math.isfinite(floor) and max(ea, eb) <= NOISE_FACTOR * floor:
        text += f" (both within {NOISE_FACTOR}× of the noise floor, so not a resolved difference)"
    return text


def _stopped(r: dict) -> str:
    """'stopped at t = ... s (cause)' for a variant that did not complete."""
    t = r.get("t_final", math.nan)
    return (f"{r['label']} did not complete ({r['status']}"
            + (f" after t = {t:.3g} s" if math.isfinite(t) else "")
            + (f": {r['message']}" if r.get("message") else "") + "), so it is left out of the ranking.")


def _cost(a: dict, b: dict) -> str:
    tf = b["wall"] / a["wall"] if a["wall"] > 0 else math.inf
    return f"cost {tf:.3g}× the wall time ({a['wall']:.3g} s → {b['wall']:.3g} s)"


def _product_pairs(var, axes, error, what, alone, floor=math.nan) -> list[str]:
    """One sentence per pair of product variants that differ in one axis only."""
    out = []
    product = [r for r in var if not r.get("alone")]
    for axis in [a for a in axes if a not in alone]:
        groups: dict[tuple, list] = {}
        for r in product:
            if axis in r["settings"]:
                groups.setdefault(_others(r["settings"], axis), []).append(r)
        for other, members in groups.items():
            order = axes[axis] if isinstance(axes, dict) else []
            # in the order the user listed the values (e.g. steps from coarse to fine)
            members.sort(key=lambda r: (order.index(r["settings"][axis])
                                        if r["settings"][axis] in order else len(order), r["wall"]))
            where = (" (with " + ", ".join(f"{k}={v}" for k, v in other) + ")") if other else ""
            for a, b in zip(members, members[1:]):
                out.append(f"Changing {axis} from {a['settings'][axis]} to {b['settings'][axis]}{where} "
                           f"{_cost(a, b)} and {_change(a, b, error, what, floor)}.")
    return out


def _alone_pairs(rows, var, error, what, floor=math.nan) -> list[str]:
    """One sentence per --alone variant against the base scene's variant."""
    base = next((r for r in var if r.get("base")), None)
    if base is None:
        return []
    out = []
    for r in rows:
        if not r.get("alone") or r["role"] != "variant":
            continue
        if r["status"] == "completed" and math.isfinite(r.get(error, math.nan)):
            out.append(f"{r['label']} instead of the base scene ({base['label']}) {_cost(base, r)} "
                       f"and {_change(base, r, error, what, floor)}.")
    return out


def chaos_sentences(chaos: dict) -> list[str]:
    """The predictability horizon and what it means for the ranking, from the numbers."""
    if chaos is None:
        return []
    thr = f"{chaos['divergence']:.3g} m RMS"
    if math.isfinite(chaos["horizon"]):
        how = ("so the study treats the scene as chaotic (chosen automatically: the noise floor "
               "reached the divergence threshold within the run)" if chaos["auto"] else
               "and the study was told the scene is chaotic (--chaotic)")
        return [f"The noise-floor rerun departs from the reference by more than {thr} at "
                f"t = {chaos['horizon']:.3g} s: that is the predictability horizon, {how}. "
                "Beyond it position errors measure chaos, not accuracy, so the variants are "
                "ranked by their centre-of-mass path (largest centre-of-mass error) and compared "
                "by energies and drape measures; RMS position errors and times to divergence are "
                "meaningful only before the horizon."]
    if chaos["forced"]:
        return [f"The noise-floor rerun stays within {_g(chaos['noise_rms_max'], ' m')} RMS of the "
                f"reference (below {thr}), but the study was told the scene is chaotic (--chaotic), "
                "so the variants are ranked by their centre-of-mass path."]
    return [f"The noise-floor rerun stays within {_g(chaos['noise_rms_max'], ' m')} RMS of the "
            f"reference, below the divergence threshold ({thr}), so the scene is not chaotic over "
            "this run and position errors rank the variants."]


def drape_sentences(rows, noise, *, support_area=0.0) -> list[str]:
    """Per drape measure: the reference's final value, the variants' final
    differences (largest and smallest) and the noise rerun's."""
    ref = next((r for r in rows if r["role"] == "reference" and "drape" in r), None)
    var = [r for r in rows if r["role"] == "variant" and r["status"] == "completed" and "drape" in r]
    if ref is None or not var:
        return []
    out = []
    for m in DRAPE_MEASURES:
        unit = DRAPE_UNITS[m] and " " + DRAPE_UNITS[m]
        key = f"{m}_final_diff"
        worst = max(var, key=lambda r: abs(r[key]))
        best = min(var, key=lambda r: abs(r[key]))
        text = (f"Final {DRAPE_NAMES[m]}: reference {_g(float(ref['drape'][m][-1]), unit)}; the variants "
                f"differ by {_g(best[key], unit)} ({best['label']}) to {_g(worst[key], unit)} "
                f"({worst['label']}), at most {_g(max(r[f'{m}_max_diff'] for r in var), unit)} over time")
        if noise is not None and key in noise:
            text += f"; the noise rerun by {_g(noise[key], unit)}"
        out.append(text + ".")
    if support_area > 0:
        out.append(f"The drape coefficient is Cusick's (A_shadow − A_disc)/(A_cloth − A_disc) with "
                   f"the sphere's shadow as the disc (A_disc = {support_area:.4g} m²).")
    else:
        out.append("The drape coefficient is the shadow area over the cloth's rest area (no support disc).")
    return out


def energy_sentence(rows, noise) -> list[str]:
    """How close the variants' total energy stays to the reference's (largest difference)."""
    var = [r for r in rows if r["role"] == "variant" and r["status"] == "completed"
           and math.isfinite(r.get("energy_error_max", math.nan))]
    if not var:
        return []
    best = min(var, key=lambda r: r["energy_error_max"])
    worst = max(var, key=lambda r: r["energy_error_max"])
    text = (f"Total energy: the largest difference from the reference's ranges from "
            f"{_g(best['energy_error_max'], ' J')} ({best['label']}) to "
            f"{_g(worst['energy_error_max'], ' J')} ({worst['label']})")
    if noise is not None and math.isfinite(noise.get("energy_error_max", math.nan)):
        text += f"; the noise rerun's is {_g(noise['energy_error_max'], ' J')}"
    return [text + "."]


def newton_sentences(rows) -> list[str]:
    """Whether the reference's Newton loops converged (diagnostics newton_unconverged)."""
    out = []
    for r in rows:
        if r["role"] != "reference" or "newton_unconverged" not in r:
            continue
        n, steps = r["newton_unconverged"], r.get("steps", 0)
        if n:
            out.append(f"The reference's Newton loop ran out of iterations on {n} of its {steps} steps "
                       f"(largest Newton residual {_g(r.get('newton_residual_max', math.nan))}), so it is "
                       "not converged to its tolerance there: its error is then that of a few Newton "
                       "iterations per step at a quarter of the finest step, not zero.")
        else:
            out.append(f"The reference's Newton loop converged on all of its {steps} steps.")
    return out


def findings(rows, axes, noise, *, error="rms_mean", chaotic=False, alone=(), chaos=None,
             support_area=0.0) -> list[str]:
    """One sentence per pair of variants that differ in one axis only (the --vary
    product), one per --alone variant against the base scene, the Pareto front,
    the noise floor and predictability horizon, drape measures, the reference's Newton."""
    var = [r for r in rows if r["role"] == "variant" and r["status"] == "completed"
           and math.isfinite(r.get(error, math.nan))]
    what = "centre-of-mass error" if chaotic else "RMS position error"
    floor = noise.get(error, math.nan) if noise is not None else math.nan
    if var and all(r[error] <= NOISE_FACTOR * floor for r in var):
        floor = math.nan          # said once, in the noise-floor sentence, not after every pair
    out = [_stopped(r) for r in rows if r["role"] == "variant" and r["status"] != "completed"]
    out += _product_pairs(var, axes, error, what, alone, floor) + _alone_pairs(rows, var, error, what, floor)
    front = [r for r in var if r.get("pareto")]
    if front:
        out.append("The Pareto front (no other variant is both faster and more accurate): "
                   + "; ".join(f"{r['label']} ({r['wall']:.3g} s, {_g(r[error], ' m')})" for r in front)
                   + ".")
    if noise is not None and math.isfinite(noise.get(error, math.nan)):
        nf = noise[error]
        below = [r["label"] for r in var if r[error] <= NOISE_FACTOR * nf]
        out.append(f"The noise floor (the reference rerun from start positions moved by "
                   f"{noise['perturb']:.0e} m) is {_g(nf, ' m')} in {what}"
                   + (("; every variant is" if len(below) == len(var) else
                       f"; {', '.join(below)} {'is' if len(below) == 1 else 'are'}")
                      + f" within {NOISE_FACTOR}× of it, so "
                      + ("no difference between variants" if len(below) == len(var) else
                         f"{'its' if len(below) == 1 else 'their'} error") + " is resolved in this measure."
                      if below else
                      f"; every variant's error is more than {NOISE_FACTOR}× above it, so the differences are real."))
    return (out + chaos_sentences(chaos) + energy_sentence(rows, noise)
            + drape_sentences(rows, noise, support_area=support_area) + newton_sentences(rows))


def _wall_sentence(rows) -> str:
    """The runs' total wall time and the reference's share (the expensive part)."""
    walls = {r["role"]: 0.0 for r in rows}
    for r in rows:
        if math.isfinite(r.get("wall", math.nan)):
            walls[r["role"]] += r["wall"]
    total = sum(walls.values())
    return (f"The runs took {total:.0f} s of wall time in all: {walls.get('variant', 0.0):.0f} s the "
            f"{sum(r['role'] == 'variant' for r in rows)} variants, {walls.get('reference', 0.0):.0f} s "
            f"the reference and {walls.get('noise', 0.0):.0f} s its noise-floor rerun (wall times on a "
            "shared machine vary between runs; errors are reproduced exactly).")


def write_markdown(path, rows, axes, noise, *, scene, command, reference_label, plots,
                   error="rms_mean", chaos=None, divergence=0.01, support_area=0.0, alone=()) -> None:
    chaotic = bool(chaos and chaos["chaotic"])
    lines = [f"# Accuracy study: {scene}", "",
             f"Command: `{command}`", "",
             f"Reference (not a variant): {reference_label}.", "",
             _wall_sentence(rows), "",
             f"Errors are measured at common output times against the reference at its material "
             f"points; divergence threshold {divergence:.3g} m RMS. The Pareto front ranks by "
             f"{'the largest centre-of-mass error' if chaotic else 'the time-averaged RMS position error'}.",
             ""]
    lines += ["## Findings", ""] + [f"- {s}" for s in findings(
        rows, axes, noise, error=error, chaotic=chaotic, alone=alone, chaos=chaos,
        support_area=support_area)] + [""]
    lines += ["## Variants", "",
              "| variant | status | wall s | RMS mean m | final m | CoM max m | energy drift J "
              "| energy err max J | max strain | penetration m | divergence s | Newton unconv. "
              "| shadow final Δ m² | CoM height final Δ m | extent final Δ m | Pareto |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|:-:|"]
    for r in rows:
        cells = [_g(r.get(k, math.nan)) for k in (
            "wall", "rms_mean", "final_error", "com_max_error", "energy_drift", "energy_error_max",
            "max_strain", "max_penetration", "time_to_divergence")]
        cells.append(str(r.get("newton_unconverged", "")))
        cells += [_g(r.get(k, math.nan)) for k in (
            "shadow_area_final_diff", "com_height_final_diff", "vertical_extent_final_diff")]
        lines.append(f"| {r['label']} | {r['status']} | " + " | ".join(cells)
                     + f" | {'●' if r.get('pareto') else ''} |")
    lines += [""] + [f"![{os.path.basename(p)}]({os.path.basename(p)})" for p in plots] + [""]
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))


ERROR_NAMES = {"rms_mean": "time-averaged RMS position error (m)",
               "com_max_error": "largest centre-of-mass error (m)"}


def _horizon(ax, chaos) -> None:
    """A vertical line at the predictability horizon, when there is one."""
    if chaos is not None and math.isfinite(chaos.get("horizon", math.nan)):
        ax.axvline(chaos["horizon"], color="tab:red", ls=":", lw=1, label="predictability horizon")


def _plot_pareto(plt, path, var, noise, error) -> None:
    """Error against wall time; points numbered, the numbers explained in the legend
    (labels written beside the points would overlap where errors coincide)."""
    fig, ax = plt.subplots(figsize=(8.4, 4.8))
    for i, r in enumerate(var, 1):
        y = max(r[error], 1e-300)
        ax.scatter([r["wall"]], [y], s=18, label=f"{i}: {r['label']}")
        ax.annotate(str(i), (r["wall"], y), xytext=(3, 3), textcoords="offset points", fontsize=7)
    front = [r for r in var if r.get("pareto")]
    if front:
        ax.plot([r["wall"] for r in front], [max(r[error], 1e-300) for r in front], "r-o",
                mfc="none", label="Pareto front")
    if noise is not None and math.isfinite(noise.get(error, math.nan)) and noise[error] > 0:
        ax.axhline(noise[error], color="gray", ls="--", label="noise floor")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel(ERROR_NAMES.get(error, error))
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _positive(v) -> np.ndarray:
    """Zeros (the shared start) as gaps on a log axis."""
    v = np.asarray(v, float)
    return np.where(v > 0, v, np.nan)


def _plot_error_time(plt, path, var, noise, chaos) -> None:
    """RMS position error and centre-of-mass error over time (Pareto variants solid)."""
    fig, axes = plt.subplots(2, 1, figsize=(6.4, 7.0), sharex=True)
    for ax, key, name in zip(axes, ("rms", "com_error"),
                             ("RMS position error (m)", "centre-of-mass error (m)")):
        for r in var:
            if "times" in r and len(r["times"]):
                ax.plot(r["times"], _positive(r[key]), "-" if r.get("pareto") else "--",
                        lw=1.6 if r.get("pareto") else 0.9,
                        label=r["label"] + (" (Pareto)" if r.get("pareto") else ""))
        if noise is not None and "times" in noise:
            ax.plot(noise["times"], _positive(noise[key]), color="gray", ls=":", lw=1.6, label="noise floor")
        _horizon(ax, chaos)
        ax.set_yscale("log")
        ax.set_ylabel(name)
    axes[-1].set_xlabel("time (s)")
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_stages(plt, path, rows, stages) -> None:
    runs = [r for r in rows if r["stages"]]
    fig, ax = plt.subplots(figsize=(6.4, 0.35 * len(runs) + 1.5))
    left = np.zeros(len(runs))
    for s in stages:
        w = np.array([r["stages"].get(s, 0.0) for r in runs])
        if np.any(w > 0):
            ax.barh(range(len(runs)), w, left=left, label=s)
            left += w
    ax.set_yticks(range(len(runs)), [r["label"] for r in runs], fontsize=6)
    ax.set_xlabel("seconds (rank 0, summed over steps)")
    ax.legend(fontsize=6, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_drape(plt, path, rows, chaos) -> None:
    """Each drape measure over time: variants, the reference (black), the noise rerun (gray)."""
    fig, axes = plt.subplots(2, 2, figsize=(9.0, 6.4), sharex=True)
    for ax, m in zip(axes.ravel(), DRAPE_MEASURES):
        for r in rows:
            if "drape" not in r or "times" not in r:
                continue
            style = {"reference": dict(color="black", lw=2.0, label="reference"),
                     "noise": dict(color="gray", ls=":", lw=1.6, label="noise rerun")}.get(
                r["role"], dict(lw=0.9, ls="-" if r.get("pareto") else "--", label=r["label"]))
            ax.plot(r["times"], r["drape"][m], **style)
        _horizon(ax, chaos)
        unit = DRAPE_UNITS[m]
        ax.set_ylabel(DRAPE_NAMES[m] + (f" ({unit})" if unit else ""))
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=6, loc="lower center", ncol=3)
    fig.tight_layout(rect=(0, 0.04 + 0.025 * math.ceil(len(labels) / 3), 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot(prefix: str, rows, noise, stages, *, error="rms_mean", chaos=None) -> list[str]:
    """error_vs_wall.png, error_vs_time.png, stage_split.png, drape.png beside ``prefix``."""
    # matplotlib takes a second to import: only the plotting pays for it
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)
    var = [r for r in rows if r["role"] == "variant" and r["status"] == "completed"
           and math.isfinite(r.get(error, math.nan))]
    paths = [prefix + n for n in ("error_vs_wall.png", "error_vs_time.png", "stage_split.png")]
    _plot_pareto(plt, paths[0], var, noise, error)
    _plot_error_time(plt, paths[1], var, noise, chaos)
    _plot_stages(plt, paths[2], rows, stages)
    if any("drape" in r for r in rows):
        paths.append(prefix + "drape.png")
        _plot_drape(plt, paths[-1], rows, chaos)
    return paths
