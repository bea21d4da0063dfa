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

from .metrics import SCALAR_METRICS


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


def findings(rows, axes, noise, *, error="rms_mean", chaotic=False) -> list[str]:
    """One sentence per pair of variants that differ in one axis only, plus the
    Pareto front and the noise floor."""
    var = [r for r in rows if r["role"] == "variant" and r["status"] == "completed"
           and math.isfinite(r.get(error, math.nan))]
    what = "centre-of-mass error" if chaotic else "RMS position error"
    out = []
    for axis in axes:
        groups: dict[tuple, list] = {}
        for r in var:
            if axis in r["settings"]:
                groups.setdefault(_others(r["settings"], axis), []).append(r)
        for other, members in groups.items():
            order = axes[axis] if isinstance(axes, dict) else []
            # in the order the user listed the values (e.g. steps from coarse to fine)
            members.sort(key=lambda r: (order.index(r["settings"][axis])
                                        if r["settings"][axis] in order else len(order), r["wall"]))
            where = (" (with " + ", ".join(f"{k}={v}" for k, v in other) + ")") if other else ""
            for a, b in zip(members, members[1:]):
                tf = b["wall"] / a["wall"] if a["wall"] > 0 else math.inf
                ea, eb = a[error], b[error]
                if eb > 0 and ea > eb:
                    change = f"cut the {what} {ea / eb:.3g}× ({_g(ea, ' m')} → {_g(eb, ' m')})"
                elif ea > 0 and eb > ea:
                    change = f"raised the {what} {eb / ea:.3g}× ({_g(ea, ' m')} → {_g(eb, ' m')})"
                else:
                    change = f"left the {what} at {_g(eb, ' m')}"
                out.append(f"Changing {axis} from {a['settings'][axis]} to {b['settings'][axis]}{where} "
                           f"cost {tf:.3g}× the wall time ({a['wall']:.3g} s → {b['wall']:.3g} s) "
                           f"and {change}.")
    front = [r for r in var if r.get("pareto")]
    if front:
        out.append("The Pareto front (no other variant is both faster and more accurate): "
                   + "; ".join(f"{r['label']} ({r['wall']:.3g} s, {_g(r[error], ' m')})" for r in front)
                   + ".")
    if noise is not None and math.isfinite(noise.get(error, math.nan)):
        nf = noise[error]
        below = [r["label"] for r in var if r[error] <= 10 * nf]
        out.append(f"The noise floor (the reference rerun from start positions moved by "
                   f"{noise['perturb']:.0e} m) is {_g(nf, ' m')}"
                   + (f"; {', '.join(below)} {'is' if len(below) == 1 else 'are'} within 10× of it, "
                      f"so {'its' if len(below) == 1 else 'their'} error is not resolved." if below else
                      "; every variant's error is more than 10× above it, so the differences are real."))
    return out


def write_markdown(path, rows, axes, noise, *, scene, command, reference_label, plots,
                   error="rms_mean", chaotic=False) -> None:
    lines = [f"# Accuracy study: {scene}", "",
             f"Command: `{command}`", "",
             f"Reference (not a variant): {reference_label}.", ""]
    if chaotic:
        lines += ["The scene is treated as chaotic: positions decorrelate, so the variants are "
                  "ranked by the centre-of-mass error, energies and the time to divergence.", ""]
    lines += ["## Findings", ""] + [f"- {s}" for s in findings(rows, axes, noise, error=error,
                                                               chaotic=chaotic)] + [""]
    lines += ["## Variants", "",
              "| variant | status | wall s | RMS mean m | final m | CoM max m | energy drift J "
              "| max strain | penetration m | divergence s | Pareto |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|:-:|"]
    for r in rows:
        lines.append(f"| {r['label']} | {r['status']} | {_g(r.get('wall', math.nan))} "
                     f"| {_g(r.get('rms_mean', math.nan))} | {_g(r.get('final_error', math.nan))} "
                     f"| {_g(r.get('com_max_error', math.nan))} | {_g(r.get('energy_drift', math.nan))} "
                     f"| {_g(r.get('max_strain', math.nan))} | {_g(r.get('max_penetration', math.nan))} "
                     f"| {_g(r.get('time_to_divergence', math.nan))} | {'●' if r.get('pareto') else ''} |")
    lines += [""] + [f"![{os.path.basename(p)}]({os.path.basename(p)})" for p in plots] + [""]
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines))


def plot(prefix: str, rows, noise, stages, *, error="rms_mean") -> list[str]:
    """error_vs_wall.png, error_vs_time.png, stage_split.png beside ``prefix``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    var = [r for r in rows if r["role"] == "variant" and math.isfinite(r.get(error, math.nan))]
    paths = []
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    ax.scatter([r["wall"] for r in var], [max(r[error], 1e-300) for r in var], c="tab:blue")
    for r in var:
        ax.annotate(r["label"], (r["wall"], max(r[error], 1e-300)), fontsize=6)
    front = [r for r in var if r.get("pareto")]
    if front:
        ax.plot([r["wall"] for r in front], [max(r[error], 1e-300) for r in front], "r-o",
                mfc="none", label="Pareto front")
    if noise is not None and math.isfinite(noise.get(error, math.nan)) and noise[error] > 0:
        ax.axhline(noise[error], color="gray", ls="--", label="noise floor")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel(f"{error} (m)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    paths.append(prefix + "error_vs_wall.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for r in var:
        if "times" in r and len(r["times"]):
            ax.plot(r["times"], np.maximum(r["rms"], 1e-300), "-" if r.get("pareto") else "--",
                    lw=1.6 if r.get("pareto") else 0.9, label=r["label"] + (" (Pareto)" if r.get("pareto") else ""))
    if noise is not None and "times" in noise:
        ax.plot(noise["times"], np.maximum(noise["rms"], 1e-300), color="gray", ls=":", label="noise floor")
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("RMS position error (m)")
    ax.legend(fontsize=6)
    fig.tight_layout()
    paths.append(prefix + "error_vs_time.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

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
    paths.append(prefix + "stage_split.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)
    return paths
