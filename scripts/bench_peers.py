#!/usr/bin/env python3
"""distcloth side by side with two peer cloth tools (Blender, Warp/Newton) on
the peer harness's reference scenes: wall time per simulated second against
error, one Pareto curve per tool (docs/peers.md).

    .venv/bin/python scripts/bench_peers.py --setup-only       # Blender (apt) + out/peers/venv
    .venv/bin/python scripts/bench_peers.py --scenes S1-41 --repeats 1
    .venv/bin/python scripts/bench_peers.py --rerun --repeats 3  # idle machine, all scenes
    .venv/bin/python scripts/bench_peers.py --report-only        # docs from the cache

Scenes S1-41, S1-101 (hanging square) and S2-81 (tablecloth on a sphere) are
those of the harness directory (--peers-dir, default ../shared/peers next to
the repository: README.md, scenes.py there); distcloth runs
configs/bench/*.yaml, the same scenes.  The harness's own scripts run
unchanged, driven by scripts/peers_blender_driver.py and
scripts/peers_newton_driver.py (positions at t = 0.5, 1, 1.5, 2 s) and
distcloth by scripts/peers_distcloth_driver.py (the stepping loop timed).

Error: RMS vertex distance over the four times against the tool's own
converged reference (Blender quality 160, Newton 20 substeps, distcloth
BDF-2 at 1 ms with ksp_rtol 1e-8, with contact as a barrier its own such
run with Newton to 1 mm/s), computed once and cached under
out/peers/ref/ (git-ignored).  Timed runs are interleaved across the tools
(A, B, C, A, B, C, ...) and cached under out/peers/runs/; a second call
only runs what is missing (--rerun: time everything again).  Before each
run the cores busy with other work over 3 s are recorded (and warned of
above a quarter of the cores): the 1-minute load average right after a run
still holds that run's own processes.  Blender and
Newton are never needed by the project's tests or scripts/setup.sh.
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "peers"
VENV = OUT / "venv"
PEER_PACKAGES = ("warp-lang==1.19.0", "newton==1.8.0", "numpy")
TIMES = (0.5, 1.0, 1.5, 2.0)
DURATION = 2.0
SCENES = {  # id: (harness scene, vertices per side, distcloth scene)
    "S1-41": ("S1", 41, "configs/bench/s1_41.yaml"),
    "S1-101": ("S1", 101, "configs/bench/s1_101.yaml"),
    "S2-81": ("S2", 81, "configs/bench/s2_81.yaml"),
}
TOOLS = ("blender", "newton", "distcloth")
# Newton's graph replay (its harness's default, ~25 % faster than plain
# launches) needs an even substep count: 6 stands for 5.
SWEEP = {
    "blender": [{"quality": q} for q in (10, 20, 40)],
    "newton": [{"substeps": s} for s in (6, 10)],
    # distcloth with the solver a user gets without a solver: section (CG, warm start,
    # ksp_rtol 1e-3 without contact, 1e-5 with; docs/benchmarks.md, "Defaults by
    # problem size"); BDF-2 also at 2.5 ms and with Newton iterated (to a relative
    # residual of 1e-4), the settings that reach the peers' errors
    "distcloth": ([{"integrator": i, "step": h, "ksp_rtol": None, "newton": 1}
                   for i, steps in (("bdf2", (0.0025, 0.005, 0.01, 0.02)),
                                    ("backward_euler", (0.005, 0.01, 0.02))) for h in steps]
                  + [{"integrator": "bdf2", "step": h, "ksp_rtol": None, "newton": k}
                     for k, steps in ((2, (0.005, 0.01)), (4, (0.005, 0.01, 0.02)))
                     for h in steps]
                  # S1 only: the largest step the energy retry makes safe on the stiff
                  # hanging square (docs/benchmarks.md, "Stiff hanging square"); with
                  # contact as constraints S2 stops at 20 ms already
                  + [{"integrator": i, "step": 1.0 / 30.0, "ksp_rtol": None, "newton": 1,
                      "bodies": False} for i in ("bdf2", "backward_euler")]
                  # S1 only: one-solve BDF-2 with its solve aimed at the step's own
                  # estimated error (linear_system.step_error_fraction) instead of
                  # the fixed ksp_rtol
                  + [{"integrator": "bdf2", "step": h, "ksp_rtol": None, "newton": 1,
                      "step_error_fraction": 1.0, "bodies": False} for h in (0.005, 0.01)]
                  # S2 only: contact as a barrier, the large steps it takes
                  # (docs/collisions.md, "Contact as a barrier")
                  + [{"integrator": "backward_euler", "step": h, "ksp_rtol": None, "newton": 1,
                      "contact": "barrier"} for h in (0.01, 0.02, 1.0 / 30.0)]),
}
REFERENCE = {"blender": {"quality": 160}, "newton": {"substeps": 20},
             "distcloth": {"integrator": "bdf2", "step": 0.001, "ksp_rtol": 1e-8, "newton": 1}}
# contact as a barrier converges to its own solution (on S2-81 ~34 mm from the
# constraints' converged run, docs/benchmarks.md): its settings are measured
# against it, the barrier's Newton converged to 1 mm/s
BARRIER_REFERENCE = {**REFERENCE["distcloth"], "contact": "barrier", "velocity_tolerance": 0.001}


def setting_key(tool: str, s: dict) -> str:
    if tool == "blender":
        return f"q{s['quality']}"
    if tool == "newton":
        return f"s{s['substeps']}"
    rtol = "default" if s["ksp_rtol"] is None else f"{s['ksp_rtol']:g}"
    newton = "" if s["newton"] == 1 else f"_newton{s['newton']}"
    contact = f"_{s['contact']}" if s.get("contact") else ""
    vtol = f"_vtol{s['velocity_tolerance']:g}" if s.get("velocity_tolerance") else ""
    aimed = f"_aimed{s['step_error_fraction']:g}" if s.get("step_error_fraction") else ""
    key = f"{s['integrator']}_{1e3 * s['step']:g}ms_rtol{rtol}{newton}{contact}{vtol}{aimed}"
    # no dots: the cached files are named stem + suffix, and a dot in the stem
    # ("2.5ms") would make Path.with_suffix cut it there, so that repeats collide
    return key.replace(".", "p")


def setting_label(tool: str, s: dict) -> str:
    if tool == "blender":
        return f"quality {s['quality']}"
    if tool == "newton":
        return f"VBD {s['substeps']} substeps"
    name = {"bdf2": "BDF-2", "backward_euler": "backward Euler"}[s["integrator"]]
    rtol = "default rtol" if s["ksp_rtol"] is None else f"rtol {s['ksp_rtol']:g}"
    newton = "" if s["newton"] == 1 else f", Newton <= {s['newton']} its"
    contact = f", contact as a {s['contact']}" if s.get("contact") else ""
    vtol = (f" (Newton to {1e3 * s['velocity_tolerance']:g} mm/s)"
            if s.get("velocity_tolerance") else "")
    if s.get("step_error_fraction"):
        rtol = f"solve aimed at {s['step_error_fraction']:g} x the step's error"
    return f"{name} {1e3 * s['step']:.3g} ms, {rtol}{newton}{contact}{vtol}"


def steps_per_sim_s(tool: str, s: dict) -> float:
    if tool == "blender":
        return 60 * s["quality"]
    if tool == "newton":
        return 60 * s["substeps"]
    return 1.0 / s["step"]


# ---------------------------------------------------------------- installation

def ensure_blender() -> str:
    exe = shutil.which("blender")
    if exe is None:
        print("installing Blender from Debian (apt-get install -y blender)", flush=True)
        subprocess.run(["apt-get", "update"], check=True)
        subprocess.run(["apt-get", "install", "-y", "--no-install-recommends", "blender"], check=True)
        exe = shutil.which("blender")
    return exe


def ensure_venv() -> Path:
    python = VENV / "bin" / "python"
    if not python.exists() or subprocess.run(
            [str(python), "-c", "import warp, newton"], capture_output=True).returncode:
        print(f"creating {VENV} with {' '.join(PEER_PACKAGES)}", flush=True)
        subprocess.run(["/usr/bin/python3", "-m", "venv", str(VENV)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "-q", *PEER_PACKAGES], check=True)
    return python


# ---------------------------------------------------------------- machine load

BUSY_WINDOW_S = 3.0


def _cpu_ticks() -> tuple[int, int]:
    """(busy, total) clock ticks of all CPUs since boot (/proc/stat)."""
    # user nice system idle iowait irq softirq steal (guest time is in user)
    f = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    idle = f[3] + (f[4] if len(f) > 4 else 0)          # idle + iowait
    return sum(f) - idle, sum(f)


def load_now(window: float = BUSY_WINDOW_S) -> dict:
    """The machine's use before a run. The 1-minute load average right after
    the previous run still holds that run's own processes (it decays over a
    minute), so the figure that says whether others are running is the CPU
    time used over a short window before the run starts, when none of ours
    run: busy_cores, in cores."""
    cores = os.cpu_count() or 1
    b0, t0 = _cpu_ticks()
    time.sleep(window)
    b1, t1 = _cpu_ticks()
    busy = cores * (b1 - b0) / max(t1 - t0, 1)
    one, five, fifteen = os.getloadavg()
    return {"load1": one, "load5": five, "load15": fifteen, "cores": cores,
            "busy_cores": busy, "busy_window_s": window, "per_core": busy / cores}


def machine() -> dict:
    from distcloth.study.report import cpu_model
    model = cpu_model()
    try:
        mem = Path("/proc/meminfo").read_text().split("\n")[0].split()[1]
        mem_gib = int(mem) / 2**20
    except OSError:
        mem_gib = float("nan")
    debian = Path("/etc/debian_version").read_text().strip() if Path("/etc/debian_version").exists() else ""
    return {"cpu": model, "cores": os.cpu_count(), "memory_gib": round(mem_gib, 1),
            "system": f"{platform.system()} {platform.release()}", "debian": debian}


# ---------------------------------------------------------------- one run per tool

def _run(cmd: list[str], log: Path) -> tuple[int, float, str]:
    t0 = time.perf_counter()
    with open(log, "w") as f:
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
        f.write(" ".join(cmd) + "\n" + p.stdout)
    return p.returncode, time.perf_counter() - t0, p.stdout


def _last_line(text: str) -> str:
    lines = text.strip().splitlines()
    return lines[-1][:200] if lines else ""


def _run_peer(cmd: list[str], npz: Path):
    """A peer driver's run: exit code, process wall time, output, its RESULT
    line and the positions it saved (None if anything is missing)."""
    code, wall, text = _run(cmd, npz.with_suffix(".log"))
    r = _result_line(text)
    d = np.load(npz) if not code and r and npz.exists() else None
    return code, wall, text, r, d


def _result_line(text: str) -> dict:
    for line in text.splitlines():
        if line.startswith("RESULT "):
            out = {}
            for part in line[7:].split():
                k, _, v = part.partition("=")
                try:
                    out[k] = float(v)
                except ValueError:
                    out[k] = v
            return out
    return {}


def run_blender(a, scene: str, s: dict, npz: Path) -> dict:
    sc, n, _ = SCENES[scene]
    cmd = [a.blender, "-b", "--factory-startup", "--python",
           str(ROOT / "scripts" / "peers_blender_driver.py"), "--", "--peers-dir", str(a.peers_dir),
           "--save", str(npz), "--times", *map(str, TIMES), "--",
           "--scene", sc, "--n", str(n), "--quality", str(s["quality"])]
    code, wall, text, r, d = _run_peer(cmd, npz)
    if d is None:
        return {"ok": False, "message": f"exit {code}: " + _last_line(text), "cmd": cmd}
    return {"ok": True, "cmd": cmd, "process_s": wall, "stepping_s": r["sim_wall_s"],
            "min_z_over_time": float(d["lowest"].min()), "threads": r.get("threads"),
            "cache_mismatch": float(d["cache_mismatch"])}


def run_newton(a, scene: str, s: dict, npz: Path) -> dict:
    sc, n, _ = SCENES[scene]
    cmd = [str(a.venv_python), str(ROOT / "scripts" / "peers_newton_driver.py"),
           "--peers-dir", str(a.peers_dir), "--save", str(npz), "--times", *map(str, TIMES), "--",
           "--scene", sc, "--n", str(n), "--runs", "1", "--quiet", "--substeps", str(s["substeps"])]
    code, wall, text, r, d = _run_peer(cmd, npz)
    if d is None:
        return {"ok": False, "message": f"exit {code}: " + _last_line(text), "cmd": cmd}
    return {"ok": True, "cmd": cmd, "process_s": wall, "stepping_s": r["sim_wall_s"],
            "min_z_over_time": r["min_z_over_time"], "hook_s": float(d["hook_s"]),
            "final_mismatch": float(d["final_mismatch"])}


def run_distcloth(a, scene: str, s: dict, npz: Path) -> dict:
    from distcloth.io.h5read import read_result

    sys.path.insert(0, str(a.peers_dir))
    import scenes

    sc, n, config = SCENES[scene]
    h5 = npz.with_suffix(".h5")
    timing = npz.with_suffix(".timing.json")
    timing.unlink(missing_ok=True)
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(a.ranks), str(ROOT / ".venv" / "bin" / "python"),
           str(ROOT / "scripts" / "peers_distcloth_driver.py"), "--save", str(timing), "--",
           config, "--set", f"time.integrator={s['integrator']}", "--set", f"time.step={s['step']}",
           *([] if s["ksp_rtol"] is None else ["--set", f"solver.ksp_rtol={s['ksp_rtol']}"]),
           *([] if s["newton"] == 1 else ["--set", f"time.newton_iterations={s['newton']}",
                                          "--set", "time.newton_tolerance=1e-4"]),
           *(["--set", f"contact.model={s['contact']}"] if s.get("contact") else []),
           *(["--set", f"contact.velocity_tolerance={s['velocity_tolerance']}"]
             if s.get("velocity_tolerance") else []),
           *(["--set", f"linear_system.step_error_fraction={s['step_error_fraction']}"]
             if s.get("step_error_fraction") else []),
           *(["--set", "output.every=0.1"] if s["step"] > 0.02 else []),
           "--output", str(h5), "--overwrite", "--quiet"]
    code, wall, text = _run(cmd, npz.with_suffix(".log"))
    if not h5.exists() or not timing.exists():
        return {"ok": False, "message": f"exit {code}: " + _last_line(text), "cmd": cmd}
    res = read_result(h5)
    t = json.loads(timing.read_text())
    if res["attrs"]["status"] not in ("completed", "completed_with_warnings"):
        return {"ok": False, "cmd": cmd, "process_s": wall,
                "message": f"stopped at step {res['attrs']['error_step']}: {res['attrs']['error']}"[:300]}
    perm = scenes.canonical_order(res["rest_positions"][:, :2], sc, n)
    frames = [int(np.argmin(np.abs(res["time"] - tt))) for tt in TIMES]
    assert np.allclose(res["time"][frames], TIMES, atol=1e-9), res["time"][frames]
    P = res["positions"][frames][:, perm]
    np.savez(npz, times=np.array(TIMES), positions=P, final=P[-1])
    # the output stage's time (rank 0) is left out of the stepping time, as the
    # peers' per-frame position reads are left out of theirs
    output_s = float(np.nansum(res["stage_time"].get("output", np.zeros(1))))
    return {"ok": True, "cmd": cmd, "process_s": wall, "stepping_s": t["stepping_s"] - output_s,
            "output_s": output_s, "loop_s": t["stepping_s"],
            "min_z_over_time": float(res["positions"][:, :, 2].min()),
            "ksp_iterations": float(np.nansum(res["diagnostics"]["ksp_iterations"]))}


RUNNERS = {"blender": run_blender, "newton": run_newton, "distcloth": run_distcloth}


# ---------------------------------------------------------------- error and figures

def figures(a, scene: str, P: np.ndarray) -> dict:
    sys.path.insert(0, str(a.peers_dir))
    import scenes

    sc, n, _ = SCENES[scene]
    return scenes.metrics(sc, n, P)


def error_against(reference: Path, npz: Path) -> dict:
    ref = np.load(reference)["positions"]
    P = np.load(npz)["positions"]
    d2 = np.sum((P - ref) ** 2, axis=2)                      # (times, vertices)
    return {"error_m": float(np.sqrt(d2.mean())),
            "error_at_m": [float(e) for e in np.sqrt(d2.mean(axis=1))]}


def measure(a, scene: str, tool: str, s: dict, stem: Path) -> dict:
    """One run of one tool and setting: its record (also written to stem.json)."""
    stem.parent.mkdir(parents=True, exist_ok=True)
    load = load_now()
    if load["per_core"] > 0.25:
        print(f"  warning: {load['busy_cores']:.2f} of {load['cores']} cores busy with other "
              f"work before this run: its time is not an idle-machine figure", flush=True)
    npz = stem.with_suffix(".npz")
    npz.unlink(missing_ok=True)
    rec = {"scene": scene, "tool": tool, "setting": s, "key": setting_key(tool, s),
           "label": setting_label(tool, s), "steps_per_sim_s": steps_per_sim_s(tool, s),
           "load_before": load, "started": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
    rec.update(RUNNERS[tool](a, scene, s, npz))
    if rec["ok"]:
        P = np.load(npz)["positions"]
        rec["figures"] = figures(a, scene, P[-1])
        rec["figures"]["min_z_over_time"] = rec.pop("min_z_over_time")
        rec["wall_per_sim_s"] = rec["stepping_s"] / DURATION
        rec["process_per_sim_s"] = rec["process_s"] / DURATION
    stem.with_suffix(".json").write_text(json.dumps(rec, indent=1))
    return rec


def reference(a, scene: str, tool: str, s: dict) -> Path | None:
    stem = OUT / "ref" / scene / f"{tool}_{setting_key(tool, s)}"
    if stem.with_suffix(".json").exists() or (tool != "distcloth" and stem.with_suffix(".npz").exists()):
        return stem.with_suffix(".npz") if stem.with_suffix(".npz").exists() else None
    if a.no_references:
        print(f"  {scene} {tool}: no cached reference ({stem}.npz), --no-references", flush=True)
        return None
    print(f"  {scene} {tool}: reference {setting_label(tool, s)} (once, cached)", flush=True)
    rec = measure(a, scene, tool, s, stem)
    if not rec["ok"]:
        print(f"  reference failed: {rec['message']}", flush=True)
        return None
    print(f"    {rec['wall_per_sim_s']:.1f} s per simulated s", flush=True)
    return stem.with_suffix(".npz")


def sweep(a, scene: str) -> None:
    contact = SCENES[scene][0] == "S2"       # the only scene with bodies
    refs = {tool: reference(a, scene, tool, REFERENCE[tool]) for tool in a.tools}
    barrier_ref = (reference(a, scene, "distcloth", BARRIER_REFERENCE)
                   if contact and "distcloth" in a.tools else None)
    if a.references_only:
        return
    lists = [[(tool, s) for s in SWEEP[tool]
              if (contact or not s.get("contact")) and not (contact and s.get("bodies") is False)]
             for tool in a.tools]
    for r in range(a.repeats):
        for group in itertools.zip_longest(*lists):      # A, B, C, A, B, C, ...
            for item in group:
                if item is None:
                    continue
                tool, s = item
                stem = OUT / "runs" / scene / f"{tool}_{setting_key(tool, s)}_r{r + 1}"
                if stem.with_suffix(".json").exists() and not a.rerun:
                    continue
                print(f"  {scene} {tool} {setting_label(tool, s)} run {r + 1}", flush=True)
                rec = measure(a, scene, tool, s, stem)
                ref = barrier_ref if s.get("contact") == "barrier" else refs[tool]
                if rec["ok"] and ref is not None:
                    rec.update(error_against(ref, stem.with_suffix(".npz")))
                    if s.get("contact") == "barrier" and refs[tool] is not None:
                        # also against the other model's converged run
                        other = error_against(refs[tool], stem.with_suffix(".npz"))
                        rec["error_constraints_m"] = other["error_m"]
                    stem.with_suffix(".json").write_text(json.dumps(rec, indent=1))
                if rec["ok"]:
                    err = f"{1e3 * rec['error_m']:.2f} mm" if "error_m" in rec else "no reference"
                    print(f"    {rec['wall_per_sim_s']:.2f} s per sim-s, error {err}, "
                          f"{rec['load_before']['busy_cores']:.2f} cores busy before", flush=True)
                else:
                    print(f"    failed: {rec['message']}", flush=True)


def default_peers_dir() -> Path:
    here = ROOT.parent / "shared" / "peers"
    if here.exists():
        return here
    try:        # a git worktree: next to the main checkout
        common = subprocess.run(["git", "rev-parse", "--path-format=absolute", "--git-common-dir"],
                                cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
        return Path(common).parent.parent / "shared" / "peers"
    except (OSError, subprocess.CalledProcessError):
        return here


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    p.add_argument("--tools", nargs="+", default=list(TOOLS), choices=list(TOOLS))
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--ranks", type=int, default=2, help="distcloth's MPI ranks")
    p.add_argument("--peers-dir", type=Path, default=default_peers_dir(),
                   help="the peer harness (default: ../shared/peers next to the repository, "
                        "the main checkout's for a git worktree)")
    p.add_argument("--rerun", action="store_true",
                   help="time every setting again (references stay cached)")
    p.add_argument("--no-references", action="store_true", help="never start a reference run")
    p.add_argument("--references-only", action="store_true",
                   help="compute the missing references and stop (their timing is not a figure, "
                        "so they may run while the machine is busy; time the settings later)")
    p.add_argument("--setup-only", action="store_true",
                   help="install Blender and the Warp/Newton venv, then stop")
    p.add_argument("--report-only", action="store_true",
                   help="write docs/peers.md and the plot from the cache")
    a = p.parse_args(argv)
    a.peers_dir = a.peers_dir.resolve()
    if not (a.peers_dir / "scenes.py").exists():
        print(f"--peers-dir {a.peers_dir}: no scenes.py (the peer harness) there", file=sys.stderr)
        return 2
    if not a.report_only:
        if "blender" in a.tools or a.setup_only:
            a.blender = ensure_blender()
        if "newton" in a.tools or a.setup_only:
            a.venv_python = ensure_venv()
        if a.setup_only:
            return 0
        for scene in a.scenes:
            print(f"{scene}:", flush=True)
            sweep(a, scene)
    import peers_report
    peers_report.write(OUT, ROOT, a.peers_dir, machine(), TIMES)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
