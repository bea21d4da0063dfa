#!/usr/bin/env python3
"""distcloth at scale: the tablecloth on the sphere at 317² (100k vertices) and
1001² (1M vertices) on 2 ranks.

The scene is configs/tablecloth_sphere.yaml with overrides (nothing else to
keep in step with it): the peers' S2 material (0.15 kg/m², membrane
1000 N/m), 10 ms backward-Euler steps, the grid at N x N, and the cloth
started ``--gap`` (5 mm) above the sphere's top instead of 0.1 m, so that the
timed steps are the phase that matters: the cloth in contact with the
sphere, sliding over it and folding, not free fall. The solver is given
explicitly: CG with GAMG on AIJ, the preset that distcloth/linalg/presets.py
chooses for the contact model at these sizes (SOR-smoothed GAMG with
contact as constraints, Chebyshev-smoothed with contact as a barrier;
docs/benchmarks.md, "Solver settings tried" and "GAMG's smoother with
contact as a barrier"), ``--preconditioner`` for another preset,
``--smooths 0`` for plain aggregation.

Per size it prints, from one process group of ``--ranks`` ranks:

* set-up: wall time of building the model, the partition and the solver's
  first set-up, and each rank's resident set (VmHWM, the peak, and VmRSS)
  after the model is built, after the simulation is prepared and at the end;
* time per step over the timed steps (after ``--warmup`` steps that pay JIT
  compilation and the first contacts), and its split from distcloth's own
  stage timers (the slowest rank's): forces (the ``force:*`` stages, each
  also listed), assembly, solve, collisions (``collision:bodies`` detection
  and ``collision:response``), output (a frame every ``--every`` steps
  through the HDF5 writer, as ``distcloth run`` does) and the rest (wall
  minus all of these: kinematics, constraints, update and its ghost
  exchange, diagnostics);
* contacts and CG iterations per step, the load average before and after,
  and the machine (cores, system, processor).

The machine is shared: the driver samples the resident set of all the
run's processes and kills the run past ``--max-gib`` (9.5) in total,
reporting how far it got; rank 0's progress lines (time and peak memory
after set-up and after each step) go to /tmp/scale/worker_N.log as the run
goes, the result file to /tmp/scale/bench_N.h5.

    .venv/bin/python scripts/bench_scale.py                          # 317² then 1001²
    .venv/bin/python scripts/bench_scale.py --sizes 317 --steps 30   # one size

The driver launches itself under ``scripts/mpiexec.sh RANKS`` once per size.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "configs" / "tablecloth_sphere.yaml"
SPHERE_TOP = 0.5          # the scene's sphere: centre z 0.25, radius 0.25


def solver_settings(smooths: int = 1, preset: str = "gamg"):
    """CG + a preset of linalg/presets.py (GAMG on AIJ) as the scene's solver:
    and linear_system: sections, with ``smooths`` prolongator
    smoothing steps (pc_gamg_agg_nsmooths; the preset's 1). 0, plain
    aggregation, needs a third less memory in the set-up and far fewer
    set-up flops, but at 317² in contact 2-3x the CG iterations
    (docs/benchmarks.md, "At scale"). Plain aggregation keeps the 0.02
    aggregation threshold the preset dropped: its piecewise-constant
    interpolation over the large aggregates of every coupling cost 1.8x a
    solve at 1001² (docs/benchmarks.md, "GAMG's aggregation threshold on
    the stiff membrane")."""
    from distcloth.linalg.presets import CONTACT_RTOL, PRECONDITIONERS
    options, mat_type = PRECONDITIONERS[preset]
    if options.get("pc_type") == "gamg":
        plain = {"pc_gamg_threshold": 0.02} if smooths == 0 else {}
        options = {**options, "pc_gamg_agg_nsmooths": smooths, **plain}
    return ({"ksp_type": "cg", **options, "ksp_rtol": CONTACT_RTOL}, {"mat_type": mat_type})


def default_preset(n: int, ranks: int, contact: str) -> str:
    """The preset a scene of N x N vertices without a solver: section gets."""
    from distcloth.linalg.presets import by_size
    return by_size(n * n, ranks, contact=True, barrier=contact == "barrier")


def scene(n: int, gap: float, step: float, out: str, every: int, smooths: int = 1,
          contact: str = "constraints", preset: str = "gamg") -> dict:
    """The tablecloth scene at N x N with the overrides above (a raw mapping)."""
    from distcloth.config.load import read_scene_file
    raw = read_scene_file(str(SCENE))
    cloth = raw["cloth"][0]
    cloth["mesh"]["grid"]["resolution"] = [n, n]
    cloth["mesh"]["center"] = [0.0, 0.0, SPHERE_TOP + gap]
    cloth["material"]["stretch"] = 1000.0        # the peers' S2 membrane, N/m
    solver, linear_system = solver_settings(smooths, preset)
    raw["solver"] = solver
    raw["linear_system"] = linear_system
    raw["time"] = {**raw["time"], "step": step, "end": 10.0}
    raw["output"] = {"file": out, "every": every * step, "preview": False}
    raw["contact"] = {"model": contact}
    return raw


def memory() -> dict:
    """This process's peak and current resident set, MiB (/proc/self/status)."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmHWM:", "VmRSS:")):
                key, value, _ = line.split()
                out[key[:-1]] = int(value) / 1024.0
    return out


def progress(comm, text: str, mem: dict | None = None) -> None:
    """A line on rank 0's output as the run goes (the 1M case takes long)."""
    peaks = comm.gather_objects(memory()["VmHWM"])
    if comm.rank == 0:
        print(f"{time.strftime('%H:%M:%S')} {text}; VmHWM per rank "
              + ", ".join(f"{p:.0f}" for p in peaks) + " MiB", flush=True)


def worker(args):
    from distcloth.linalg.petsc import command_line_options, init_petsc
    init_petsc(args.petsc.split())
    # the options given here win over the script's preset, as on distcloth's command line
    given = command_line_options()
    from distcloth.config.load import config_from_dict
    from distcloth.parallel.comm import Comm
    from distcloth.run import open_writer
    from distcloth.scene import build_model
    from distcloth.simulation import Simulation
    comm = Comm()
    out = f"/tmp/scale/bench_{args.n}.h5"
    if comm.rank == 0:
        os.makedirs(os.path.dirname(out), exist_ok=True)
        if os.path.exists(out):
            os.remove(out)
    comm.synchronize()
    cfg = config_from_dict(scene(args.n, args.gap, args.step, out, args.every, args.smooths,
                                 args.contact, args.preconditioner), str(SCENE.parent),
                          str(SCENE))
    mem = {"start": memory()}
    t0 = time.perf_counter()
    model = build_model(cfg)
    mem["model"] = memory()
    progress(comm, "model built", mem)
    sim = Simulation(cfg, model, comm, cmdline_options=given, quiet=True)
    sim.prepare()
    mem["prepared"] = memory()
    writer = open_writer(sim, cfg, comm, out, sim.diagnostic_names(),
                         {"steps": args.warmup + args.steps, "output_every_steps": args.every})
    mem["writer"] = memory()
    comm.synchronize()
    setup = time.perf_counter() - t0
    progress(comm, f"set up in {setup:.1f} s", mem)

    calls: dict[str, int] = {}

    def one_step(k):
        """A step as ``distcloth run`` takes it; its stage times, output included."""
        d = sim.step()
        times, counts = sim.pipeline.take_step_counters()
        writer.write_step(sim.state.step, sim.state.t, d, times, counts)
        if k % args.every == 0:
            sim.pipeline.run("output", writer)
            times["output"] += sim.pipeline.take_step_counters()[0]["output"]
        for name, c in counts.items():
            calls[name] = calls.get(name, 0) + c
        return d, times

    t0 = time.perf_counter()
    for k in range(1, args.warmup + 1):
        s0 = time.perf_counter()
        one_step(k)
        progress(comm, f"warm-up step {k}: {time.perf_counter() - s0:.2f} s")
    comm.synchronize()
    warm = time.perf_counter() - t0
    stages: dict[str, float] = {}
    calls.clear()
    prof = None
    if args.profile:
        import cProfile
        prof = cProfile.Profile()
        prof.enable()
    walls, its, touching, t_walls = [], [], [], time.perf_counter()
    for k in range(args.warmup + 1, args.warmup + args.steps + 1):
        s0 = time.perf_counter()
        d, times = one_step(k)
        walls.append(time.perf_counter() - s0)
        progress(comm, f"step {k}: {walls[-1]:.2f} s, {d['ksp_iterations']} CG iterations")
        for name, sec in times.items():
            stages[name] = stages.get(name, 0.0) + sec
        stages["wall"] = stages.get("wall", 0.0) + walls[-1]
        its.append(d["ksp_iterations"])
        touching.append(d.get("contacts", 0))
    comm.synchronize()
    total = time.perf_counter() - t_walls
    if prof is not None:
        import pstats
        prof.disable()
        with open(f"/tmp/scale/profile_{args.n}_rank{comm.rank}.txt", "w") as f:
            pstats.Stats(prof, stream=f).sort_stats("cumulative").print_stats(60)
            pstats.Stats(prof, stream=f).sort_stats("tottime").print_stats(40)
    mem["end"] = memory()
    writer.close("completed")
    names = sorted(stages)
    local = np.array([stages[k] / args.steps for k in names])
    mx = comm.max(local)
    res = {"n": args.n, "vertices": model.num_vertices, "ranks": comm.size,
           "preconditioner": args.preconditioner,
           "setup_s": setup, "warmup_s": warm, "step_s": total / args.steps,
           "step_max_s": float(comm.max(np.array([max(walls)]))[0]),
           "stages_max": {k: float(v) for k, v in zip(names, mx)},
           "calls_per_step": {k: v / args.steps for k, v in calls.items() if v},
           "ksp_its": float(np.mean(its)), "touching": float(np.mean(touching)),
           "t_end": sim.state.t, "imbalance": sim.layout.imbalance,
           "memory": comm.gather_objects(mem)}
    if comm.rank == 0:
        print("RESULT " + json.dumps(res), flush=True)
    sim.destroy()


def _session_rss(sid: int) -> int:
    """Resident bytes of every process of session ``sid`` (the launcher and its ranks)."""
    total = 0
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            if os.getsid(int(pid)) != sid:
                continue
            with open(f"/proc/{pid}/status") as f:
                for line in f:
                    if line.startswith("VmRSS:"):
                        total += int(line.split()[1]) * 1024
        except (OSError, ValueError):
            continue
    return total


def run_watched(cmd, limit: float, log: str):
    """Run ``cmd`` in its own session, sampling its total resident set; the
    machine is shared, so past ``limit`` bytes the session is killed.
    Returns (stdout, stderr, peak total bytes, killed); stdout also in ``log``."""
    import signal
    import tempfile
    with open(log, "w+") as out, tempfile.TemporaryFile("w+") as err:
        p = subprocess.Popen(cmd, stdout=out, stderr=err, text=True, cwd=ROOT,
                             start_new_session=True)
        peak, killed = 0, False
        while p.poll() is None:
            peak = max(peak, _session_rss(p.pid))
            if peak > limit:
                os.killpg(p.pid, signal.SIGKILL)
                killed = True
                p.wait()
                break
            time.sleep(0.5)
        out.seek(0)
        err.seek(0)
        return out.read(), err.read(), peak, killed


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, default=317, help=argparse.SUPPRESS)
    ap.add_argument("--sizes", type=int, nargs="+", default=[317, 1001])
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--steps", type=int, default=20, help="timed steps")
    ap.add_argument("--warmup", type=int, default=10, help="untimed steps before")
    ap.add_argument("--gap", type=float, default=0.005, help="start height above the sphere, m")
    ap.add_argument("--step", type=float, default=0.01, help="time step, s")
    ap.add_argument("--profile", action="store_true",
                    help="cProfile the timed steps, /tmp/scale/profile_N_rankR.txt")
    ap.add_argument("--petsc", default="", help="PETSc options for the workers, e.g. '-log_view'")
    ap.add_argument("--max-gib", type=float, default=9.5,
                    help="kill a run whose ranks hold more than this in total (shared machine)")
    ap.add_argument("--smooths", type=int, default=1,
                    help="GAMG prolongator smoothing steps (pc_gamg_agg_nsmooths; the preset's: 1)")
    ap.add_argument("--every", type=int, default=5, help="a frame every so many steps")
    ap.add_argument("--contact", choices=("constraints", "barrier"), default="constraints",
                    help="contact.model (docs/collisions.md)")
    from distcloth.linalg.presets import PRECONDITIONERS
    ap.add_argument("--preconditioner", choices=sorted(PRECONDITIONERS), default=None,
                    help="a preset of distcloth/linalg/presets.py (default: the one a scene "
                         "of this size and contact model gets)")
    args = ap.parse_args()
    if args.worker:
        worker(args)
        return
    for n in args.sizes:
        load0 = os.getloadavg()
        cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(args.ranks), sys.executable, __file__,
               "--worker", "--n", str(n), "--steps", str(args.steps), "--warmup",
               str(args.warmup), "--gap", str(args.gap), "--step", str(args.step),
               "--every", str(args.every), "--smooths", str(args.smooths),
               "--contact", args.contact,
               "--preconditioner", args.preconditioner or default_preset(n, args.ranks, args.contact)]\
            + ["--profile"] * args.profile + [f"--petsc={args.petsc}"]
        t0 = time.perf_counter()
        os.makedirs("/tmp/scale", exist_ok=True)
        stdout, stderr, peak_total, killed = run_watched(cmd, args.max_gib * 2 ** 30,
                                                         f"/tmp/scale/worker_{n}.log")
        wall = time.perf_counter() - t0
        if killed:
            print(f"{n}x{n}: stopped at {peak_total / 2 ** 30:.2f} GiB resident in total "
                  f"(--max-gib {args.max_gib})", flush=True)
            continue
        res = None
        for line in stdout.splitlines():
            if line.startswith("RESULT "):
                res = json.loads(line[7:])
        if res is None:
            sys.stderr.write(stdout[-3000:] + stderr[-5000:])
            continue
        res["peak_total_gib"] = peak_total / 2 ** 30
        res["process_s"], res["load_before"], res["load_after"] = wall, load0, os.getloadavg()
        from distcloth.study.report import machine
        res["machine"] = machine()
        print(json.dumps(res, indent=1), flush=True)
        print(summary(res), flush=True)


def summary(res: dict) -> str:
    """The figures of one size as a few lines of text."""
    st, calls = res["stages_max"], res["calls_per_step"]
    forces = sum(v for k, v in st.items() if k.startswith("force:"))
    collisions = st.get("collision:bodies", 0.0) + st.get("collision:response", 0.0)
    named = forces + st["assembly"] + st["solve"] + collisions + st["output"]
    lines = [f"{res['n']}x{res['n']} ({res['vertices']} vertices), {res['ranks']} ranks: "
             f"set-up {res['setup_s']:.1f} s, {res['step_s']:.2f} s per step (slowest "
             f"{res['step_max_s']:.2f} s) to t = {res['t_end']:g} s, CG with "
             f"{res['preconditioner']}",
             f"  split per step (slowest rank): forces {forces:.2f} s (membrane "
             f"{st['force:membrane']:.2f}, bending {st['force:bending']:.2f}), assembly "
             f"{st['assembly']:.2f}, solve {st['solve']:.2f}, collisions {collisions:.2f} "
             f"(detection {st.get('collision:bodies', 0.0):.2f}, response "
             f"{st.get('collision:response', 0.0):.2f}), output {st['output']:.2f}, rest "
             f"{max(0.0, st['wall'] - named):.2f}",
             f"  solves per step {calls.get('solve', 0):.1f}, CG iterations of the last "
             f"{res['ksp_its']:.1f}, contacts {res['touching']:.0f}",
             "  peak resident set per rank (VmHWM, MiB): "
             + "; ".join(", ".join(f"{k} {v['VmHWM']:.0f}" for k, v in m.items())
                         for m in res["memory"])
             + f"; all processes {res['peak_total_gib']:.2f} GiB",
             f"  load average before {res['load_before'][0]:.1f}, after {res['load_after'][0]:.1f}; "
             f"{res['machine']}"]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
