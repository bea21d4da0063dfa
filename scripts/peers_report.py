"""docs/peers.md and docs/pictures/peers_pareto.png from the runs cached by
scripts/bench_peers.py (out/peers/runs/, out/peers/ref/)."""
from __future__ import annotations

import json
import re
import statistics
from collections import defaultdict
from pathlib import Path

TOOL_NAMES = {"blender": "Blender 3.4.1", "newton": "Newton 1.8 VBD (Warp 1.19, CPU)",
              "distcloth": "distcloth (2 ranks)"}
SCENE_TITLES = {"S1-41": "S1 hanging square, 41 x 41", "S1-101": "S1 hanging square, 101 x 101",
                "S2-81": "S2 tablecloth on a sphere, 81 x 81"}

INTRO = """\
# distcloth next to Blender and Newton

Written by `scripts/bench_peers.py` (do not edit by hand: rerun it, or
`--report-only` to rewrite this page from the cached runs).  The scenes are
those of the peer harness (`/work/shared/peers`: README.md, scenes.py,
results.md); distcloth runs the same scenes from `configs/bench/`.

**What is compared.**  Each tool runs a few settings (Blender: cloth quality,
i.e. implicit steps per 1/60 s frame; Newton: VBD substeps per frame, 10
iterations; distcloth: integrator, step and Newton iterations, with the solver a
user gets without a `solver:` section, 2 MPI ranks).
For each: the wall time of the stepping loop per simulated second, and the
error, the RMS vertex distance over t = 0.5, 1, 1.5 and 2 s against **the
tool's own converged reference** (Blender quality 160, Newton 20 substeps,
distcloth BDF-2 at 1 ms with ksp_rtol 1e-8).  Errors therefore measure how far
each tool's cheap settings are from what that tool converges to, not whether
the tools agree with each other; the physical figures (stretch, lowest point,
gap to the sphere) show the latter.  On S2, distcloth's settings with contact
as a barrier (`contact.model: barrier`, docs/collisions.md) are a different
contact model that converges to its own solution: they are measured against
its converged run (the same BDF-2 at 1 ms, Newton to 1 mm/s), and their
distance to the constraints' reference is given in brackets.

**Scene settings** (`configs/bench/*.yaml`, and why):
- vertex order `j*n + i`, x fastest, the whole edge x = 0 pinned (S1), as the harness;
  positions of every tool are mapped with `scenes.canonical_order`;
- membrane: FE triangles (`model: fem`, Green strain), the model of Newton, the only peer whose
  membrane law is given in SI units (Newton's `tri_ke = tri_ka = 1000` N/m are the Lamé moduli
  mu and lambda of its triangles: Y = 4 mu (mu + lambda) / (2 mu + lambda) = 2666.7 N/m,
  nu = 1/3, G = mu = 1000 N/m).  Blender's springs are mapped from 1000 N/m only to an order of
  magnitude (harness README), so no spring material would match it better;
- Newton cuts every grid quad along the other diagonal than distcloth's `regular` pattern: the
  mirror image in y, which these y-symmetric scenes do not tell apart;
- masses uniform, density * area / N per vertex (`mass_lumping: uniform`), as both peers;
  distcloth's default (area lumping) would give edge and corner vertices half and a quarter
  of an interior vertex's mass;
- bending: dihedral, B = 1e-6 N m (Newton: `edge_ke = 1e-3` per unit hinge length, a few
  1e-6 N m at these spacings; the bending length (B / (rho g))^(1/3) is ~1 cm, small
  against the 0.5-1 m cloth);
- no damping: Newton's `tri_kd = 0.01` against mu = 1000 N/m is a relaxation time of
  ~1e-5 s, negligible; Blender keeps its default spring damping ratios (harness);
- S2 contact: offset 5 mm (Newton's `particle_radius`), Coulomb friction 0.5 (Newton's
  `soft_contact_mu`) on sphere and floor; Blender rests ~30 mm off (its collision distance
  15 mm + collider thickness 20 mm), so gaps differ by settings, not accuracy.

**Timing.**  Blender and Newton: the harness's own stepping-loop timers (Blender uses both
cores; Warp's CPU backend one thread).  distcloth: the loop over the steps (run's
`write_steps`) minus its output stage (HDF5 frames every 20 ms; the peers' per-frame
position reads are outside their timers too), and, separately, the whole process
(`mpiexec` start, imports, numba cache load, set-up, partition, output).  The runs are
interleaved across tools (A, B, C, A, B, C) so that a change of machine load hits all
three; before each run the cores busy with other work over 3 s are recorded (with the
1-minute load average, which still holds the previous run's own processes).  Newton's graph replay needs
an even substep count, so 6 substeps stand in for 5.  How the peers' positions at the four
times are read: Blender's point cache after the run (untimed), Newton's state after the
wanted frames' replays (a hook measured at < 1 ms per run).
"""


def _records(folder: Path):
    """The run records in folder/<scene>/ (not distcloth's timing files)."""
    for path in sorted(folder.glob("*/*.json")):
        if not path.name.endswith(".timing.json"):
            yield json.loads(path.read_text())


def _load(out: Path):
    runs = defaultdict(list)
    for rec in _records(out / "runs"):
        runs[(rec["scene"], rec["tool"], rec["key"])].append(rec)
    refs = defaultdict(list)
    for rec in _records(out / "ref"):
        refs[(rec["scene"], rec["tool"])].append(rec)
    return runs, refs


def _summary(recs):
    ok = [r for r in recs if r["ok"]]
    first = ok[0] if ok else recs[0]
    row = {"tool": first["tool"], "key": first["key"], "label": first["label"],
           "steps": first["steps_per_sim_s"], "ok": bool(ok), "runs": len(recs),
           "setting": first.get("setting", {}),
           "load": _load_cell([r["load_before"] for r in recs]),
           "message": "" if ok else recs[0].get("message", "")}
    if ok:
        row["wall"] = statistics.median(r["wall_per_sim_s"] for r in ok)
        row["walls"] = [r["wall_per_sim_s"] for r in ok]
        row["process"] = statistics.median(r["process_per_sim_s"] for r in ok)
        row["error"] = first.get("error_m")
        row["error_at"] = first.get("error_at_m")
        row["error_other"] = first.get("error_constraints_m")
        row["figures"] = first["figures"]
    return row


def _load_cell(loads) -> str:
    """The most other work seen before a setting's runs, in busy cores (records
    written before the script measured it: a dash), and the largest 1-minute
    load average."""
    busy = [l["busy_cores"] for l in loads if "busy_cores" in l]
    cell = f"{max(busy):.2f}" if len(busy) == len(loads) else "–"
    return f"{cell} ({max(l['load1'] for l in loads):.2f})"


def _mm(x, digits=1):
    return "–" if x is None else f"{1e3 * x:.{digits}f}"


def _figure_cells(f, scene):
    cells = [f"{100 * f['max_edge_stretch']:.2f}", f"{f['min_z']:.4f}", f"{f['min_z_over_time']:.4f}"]
    if scene.startswith("S2"):
        cells.append(_mm(f.get("min_dist_to_sphere")))
    return cells


def _row(row, scene, width):
    if not row["ok"]:
        cells = [row["tool"], row["label"], f"{row['steps']:g}",
                 "**failed**: " + row["message"].replace("|", "/")] + ["–"] * (width - 6) \
            + [row["load"], str(row["runs"])]
        return "| " + " | ".join(cells) + " |"
    walls = ", ".join(f"{w:.2f}" for w in row["walls"])
    cells = [row["tool"], row["label"], f"{row['steps']:g}",
             f"{row['wall']:.2f}" + (f" ({walls})" if len(row["walls"]) > 1 else ""),
             f"{row['process']:.2f}" if row["tool"] == "distcloth" else "",
             _mm(row["error"]) + (f" ({_mm(row['error_other'])})" if row.get("error_other") else ""),
             " / ".join(_mm(e) for e in row["error_at"]) if row["error_at"] else "–",
             *_figure_cells(row["figures"], scene), row["load"], str(row["runs"])]
    return "| " + " | ".join(cells) + " |"


def _table(scene, rows, ref_rows):
    s2 = scene.startswith("S2")
    head = ["tool", "setting", "steps per sim-s", "wall s per sim-s (stepping)",
            "distcloth process s per sim-s", "error mm (RMS, 0.5-2 s)",
            "error mm at 0.5 / 1 / 1.5 / 2 s", "max stretch %", "min z at 2 s [m]",
            "min z over time [m]"] + (["gap to sphere mm"] if s2 else []) + ["cores busy before (1-min load)", "runs"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for tool in ("blender", "newton", "distcloth"):
        for row in (r for r in rows if r["tool"] == tool):
            lines.append(_row(row, scene, len(head)))
        for ref in (r for r in ref_rows if r["tool"] == tool and r["ok"]):
            cells = [ref["tool"], ref["label"] + " (reference)", f"{ref['steps_per_sim_s']:g}",
                     f"{ref['wall_per_sim_s']:.2f}",
                     f"{ref['process_per_sim_s']:.2f}" if tool == "distcloth" else "",
                     "0 (reference)", "", *_figure_cells(ref["figures"], scene),
                     _load_cell([ref["load_before"]]), "1"]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _matches(rows):
    """(peer row, the cheapest distcloth row at equal or lower error, or None)
    for every measured peer setting."""
    ours = [r for r in rows if r["tool"] == "distcloth" and r["ok"] and r["error"] is not None]
    out = []
    for p in rows:
        if p["tool"] == "distcloth" or not p["ok"] or p["error"] is None:
            continue
        match = [d for d in ours if d["error"] <= p["error"]]
        out.append((p, min(match, key=lambda r: r["wall"]) if match else None))
    return out


def _ratios(rows):
    """For each peer setting: the cheapest distcloth setting at equal or lower
    error, and how many times faster it is per simulated second."""
    lines = ["| peer setting | peer error mm | peer s per sim-s | distcloth at equal or lower error "
             "| its error mm | its s per sim-s (stepping / process) | ratio (stepping / process) |",
             "|---|---|---|---|---|---|---|"]
    best = None
    for p, d in _matches(rows):
        if d is None:
            lines.append(f"| {p['tool']} {p['label']} | {_mm(p['error'])} | {p['wall']:.2f} | "
                         f"no distcloth setting measured reaches this error | | | |")
            continue
        ratio, ratio_p = p["wall"] / d["wall"], p["wall"] / d["process"]
        lines.append(f"| {p['tool']} {p['label']} | {_mm(p['error'])} | {p['wall']:.2f} | {d['label']} | "
                     f"{_mm(d['error'])} | {d['wall']:.2f} / {d['process']:.2f} | "
                     f"{ratio:.2f} / {ratio_p:.2f} |")
        if best is None or ratio < best[0]:
            best = (ratio, p, d)
    return "\n".join(lines), best


def _in_use(row) -> bool:
    """The peer settings their users run (the comparison the speed target
    names): Blender quality 20 or better, Newton 10 substeps or more."""
    s = row.get("setting", {})
    if row["tool"] == "blender":
        return s.get("quality", 0) >= 20
    if row["tool"] == "newton":
        return s.get("substeps", 0) >= 10
    return False


def _target_line(rows) -> str:
    """Against the peer settings in use: the smallest speed ratio, and the
    settings no distcloth setting matches in error."""
    pairs = [(p, d) for p, d in _matches(rows) if _in_use(p)]
    if not pairs:
        return ""
    ratios = [(p["wall"] / d["wall"], p, d) for p, d in pairs if d is not None]
    unmatched = [f"{p['tool']} {p['label']} ({_mm(p['error'])} mm)" for p, d in pairs if d is None]
    text = "Against the peer settings in use (Blender quality 20 or better, Newton 10 substeps or more): "
    if ratios:
        ratio, p, d = min(ratios, key=lambda t: t[0])
        text += (f"smallest ratio {ratio:.2f}x (distcloth {d['label']} against "
                 f"{p['tool']} {p['label']})")
    else:
        text += "no ratio"
    if unmatched:
        text += "; no distcloth setting measured reaches the error of " + ", ".join(unmatched)
    return text + ".\n"


def _point_label(row) -> str:
    """A plotted point's setting, short: q20, s10, 5 ms, BE 33.3 ms, 10 ms N<=4."""
    s = row.get("setting") or {}
    if row["tool"] == "blender":
        return f"q{s.get('quality', '?')}"
    if row["tool"] == "newton":
        return f"s{s.get('substeps', '?')}"
    if "step" not in s:            # a record written before settings were kept
        return row["key"].split("_rtol")[0].replace("backward_euler_", "BE ").replace("bdf2_", "")
    text = f"{1e3 * s['step']:.3g} ms"
    if s.get("integrator") == "backward_euler":
        text = "BE " + text
    if s.get("newton", 1) > 1:
        text += f" N<={s['newton']}"
    if s.get("step_error_fraction"):
        text += " aimed"
    return text


def _plot(scenes_rows, path: Path, note: str):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = [s for s in SCENE_TITLES
              if any(r["ok"] and r.get("error") for r in scenes_rows.get(s, []))]
    if not scenes:
        return False
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.2 * len(scenes), 5.4), squeeze=False)
    style = {"blender": ("tab:orange", "s"), "newton": ("tab:green", "^"),
             "bdf2": ("tab:blue", "o"), "backward_euler": ("tab:purple", "D"),
             "bdf2_newton": ("tab:cyan", "v"), "barrier": ("tab:red", "P")}
    for ax, scene in zip(axes[0], scenes):
        series = defaultdict(list)
        for r in scenes_rows[scene]:
            if r["ok"] and r.get("error"):
                name = r["tool"] if r["tool"] != "distcloth" else r["key"].split("_")[0] \
                    if not r["key"].startswith("backward") else "backward_euler"
                if "_newton" in r["key"]:
                    name += "_newton"
                if r["key"].endswith("_barrier"):
                    name = "barrier"
                series[name].append(r)
        for name, rs in series.items():
            rs.sort(key=lambda r: r["wall"])
            color, marker = style[name]
            label = {"blender": "Blender (quality)", "newton": "Newton VBD (substeps)",
                     "bdf2": "distcloth BDF-2", "backward_euler": "distcloth backward Euler",
                     "bdf2_newton": "distcloth BDF-2, Newton iterated",
                     "barrier": "distcloth backward Euler, contact as a barrier"}[name]
            ax.loglog([r["wall"] for r in rs], [1e3 * r["error"] for r in rs], marker=marker,
                      color=color, label=label)
            for r in rs:
                ax.annotate(_point_label(r), (r["wall"], 1e3 * r["error"]), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
        ax.set_title(SCENE_TITLES[scene])
        ax.set_xlabel("wall s per simulated s (stepping loop)")
        ax.set_ylabel("error mm (RMS vs own reference)")
        ax.grid(True, which="both", alpha=0.3)
        # below the axes: inside, it hides points of the lower-left corner
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)
    fig.suptitle(note, fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def _kept_sections(page: Path) -> dict:
    """The scene sections of an earlier page, for scenes whose runs are not
    in this cache (the runs stay on the machine that made them): kept as
    they were, marked as such and with the machine that measured them,
    rather than dropped."""
    if not page.exists():
        return {}
    text = page.read_text().split("\n## Commands")[0]
    machine = re.search(r"^\*\*Machine\*\*: (.*?)\. Scenes of", text, re.M)
    out = {}
    for scene, title in SCENE_TITLES.items():
        head = f"## {title}\n"
        if head not in text:
            continue
        body = text.split(head, 1)[1].split("\n## ", 1)[0].strip() + "\n"
        if "Not measured yet" in body:
            continue
        if KEPT_NOTE.match(body):      # kept before: its note names the machine, if any
            out[scene] = head + "\n" + body
        else:
            on = f" on {machine.group(1)}" if machine else ""
            out[scene] = head + "\n" + kept_note(on) + body
    return out


KEPT_NOTE = re.compile(r"From an earlier run of this script[^\n]*\n\n")


def kept_note(on: str) -> str:
    return (f"From an earlier run of this script{on}, whose runs are not in this machine's "
            "cache (out/peers/runs/): kept as that run wrote it, with its load figures.\n\n")


def write(out: Path, root: Path, peers_dir: Path, machine: dict, times) -> None:
    runs, refs = _load(out)
    kept = _kept_sections(root / "docs" / "peers.md")
    order = {"blender": 0, "newton": 1, "distcloth": 2}
    scenes_rows = defaultdict(list)
    for (scene, tool, key), recs in runs.items():
        scenes_rows[scene].append(_summary(recs))
    before = [r["load_before"] for recs in runs.values() for r in recs]
    loads = [l["load1"] for l in before]
    busy = [l["busy_cores"] for l in before if "busy_cores" in l]
    busy_text = (f"{min(busy):.2f} to {max(busy):.2f}" if busy else "not measured (records of an "
                 "earlier version of the script)")
    text = [INTRO]
    plotted = [sc for sc in SCENE_TITLES if scenes_rows.get(sc)]
    text.append(f"**Machine**: {machine['cpu']}, {machine['cores']} cores, {machine['memory_gib']} GiB, "
                f"Debian {machine['debian']} ({machine['system']}). Scenes of this cache's runs: "
                f"{', '.join(plotted) or 'none'}; cores busy with other work over the "
                f"3 s before each run: {busy_text} of {machine['cores']} (above "
                f"{0.25 * machine['cores']:g} the times are not idle-machine figures); 1-minute "
                f"load average before them {min(loads, default=0):.2f} to {max(loads, default=0):.2f}, "
                f"which still holds the previous run's own processes.\n")
    text.append("![error against wall time per simulated second](pictures/peers_pareto.png)\n")
    if plotted and any(sc in kept for sc in SCENE_TITLES if sc not in plotted):
        text.append(f"(The plot shows {', '.join(plotted)}, the scenes of this cache's runs.)\n")
    for scene in ("S1-41", "S1-101", "S2-81"):
        rows = sorted(scenes_rows.get(scene, []), key=lambda r: (order[r["tool"]], -r.get("wall", 0)))
        if not rows:
            if scene in kept:
                text.append(kept[scene])
            else:
                text.append(f"## {SCENE_TITLES[scene]}\n\nNot measured yet: "
                            f"`.venv/bin/python scripts/bench_peers.py --scenes {scene}`.\n")
            continue
        ref_rows = [r for t in ("blender", "newton", "distcloth") for r in refs.get((scene, t), [])]
        text.append(f"## {SCENE_TITLES[scene]}\n\n" + _table(scene, rows, ref_rows) + "\n")
        table, best = _ratios(rows)
        text.append("Speed at equal error (each peer setting against the cheapest distcloth "
                    "setting whose error is not larger):\n\n" + table + "\n")
        if best is not None:
            ratio, p, d = best
            text.append(f"Smallest ratio: distcloth {d['label']} is {ratio:.2f}x as fast per simulated "
                        f"second (stepping loop) as {p['tool']} {p['label']} at equal or lower error.\n")
        target = _target_line(rows)
        if target:
            text.append(target)
        missing = [t for t in ("blender", "newton", "distcloth") if not refs.get((scene, t))]
        if missing:
            text.append(f"References recorded by an earlier version of the script or not yet run: "
                        f"{', '.join(missing)} (errors use the cached positions under out/peers/ref/).\n")
    text.append(COMMANDS)
    (root / "docs" / "peers.md").write_text("\n".join(text))
    for part in text[3:-1]:          # the scenes' tables, also on the console
        print(part)
    _plot(scenes_rows, root / "docs" / "pictures" / "peers_pareto.png",
          f"cores busy with other work before the runs: {busy_text} of {machine['cores']}")
    print(f"wrote {root / 'docs' / 'peers.md'} and docs/pictures/peers_pareto.png", flush=True)


COMMANDS = """\
## Commands

```
.venv/bin/python scripts/bench_peers.py --setup-only      # Blender (Debian), Warp + Newton (out/peers/venv)
.venv/bin/python scripts/bench_peers.py --scenes S1-101 --references-only   # the long references, any time
.venv/bin/python scripts/bench_peers.py --scenes S1-41 --repeats 1
.venv/bin/python scripts/bench_peers.py --rerun --repeats 3   # all scenes, idle machine
.venv/bin/python scripts/bench_peers.py --report-only         # this page from out/peers/
```

One run of each tool, as the script starts it (logs next to the cached runs, first line the command):

```
blender -b --factory-startup --python scripts/peers_blender_driver.py -- --peers-dir PEERS \\
    --save X.npz --times 0.5 1.0 1.5 2.0 -- --scene S1 --n 41 --quality 20
out/peers/venv/bin/python scripts/peers_newton_driver.py --peers-dir PEERS --save X.npz \\
    --times 0.5 1.0 1.5 2.0 -- --scene S1 --n 41 --runs 1 --quiet --substeps 10
scripts/mpiexec.sh 2 .venv/bin/python scripts/peers_distcloth_driver.py --save X.timing.json -- \\
    configs/bench/s1_41.yaml --set time.integrator=bdf2 --set time.step=0.005 \\
    --output X.h5 --overwrite --quiet
```

References are run once per scene and tool and cached under `out/peers/ref/` (git-ignored),
keyed by their settings; delete a file there to recompute it.  Their cost, from the harness's
results.md (quality 20 and 10 substeps) scaled by the step count: Blender quality 160 about
2 min on S1-41, ~28 min on S1-101 and ~45 min on S2-81; Newton 20 substeps about 2.6 min,
~13 min and ~9 min; distcloth BDF-2 at 1 ms a few minutes on S1-41 (measured above).
"""
