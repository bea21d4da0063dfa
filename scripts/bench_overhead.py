#!/usr/bin/env python3
"""What a step costs besides CG's arithmetic, measured on a shared machine.

    .venv/bin/python scripts/bench_overhead.py steps SCENE.yaml [key=YAML ...]
        CPU and wall ms per step (minimum over 4 blocks of 20 steps after 5
        warm-up steps: robust to other users' load) and CG its per step;
        key=DELETE drops a top-level section (solver=DELETE: the size preset)
    .venv/bin/python scripts/bench_overhead.py membrane STATE.npy
        CPU ms of one FE membrane evaluation with Hessians on the tablecloth
        (configs/tablecloth_sphere.yaml) at rest and at the saved positions
        (``tablecloth-state`` writes them)
    .venv/bin/python scripts/bench_overhead.py tablecloth-state STATE.npy [STEPS]
        run the tablecloth STEPS steps (80: draped at t = 0.4 s), save its positions
    .venv/bin/python scripts/bench_overhead.py startup PROFILE
        the split of ``python -m cProfile -o PROFILE -m distcloth run ...``
    .venv/bin/python scripts/bench_overhead.py tablecloth-stage
        the tablecloth's FE membrane stage per step before first contact (steps
        2-25) and after (31-80): calls and wall ms (stage timers), and the
        whole step's CPU ms
    .venv/bin/python scripts/bench_overhead.py profile SCENE.yaml [STEPS]
        cProfile of STEPS steps (100) after 3 warm-up steps, by own time

docs/benchmarks.md, "Per-iteration overhead, the membrane after contact,
start-up, and defaults by size", has the figures and the commands.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
TABLECLOTH = ROOT / "configs" / "tablecloth_sphere.yaml"


def _sim(raw):
    from distcloth.inprocess import build_simulation
    from distcloth.parallel.comm import Comm
    sim, _, err = build_simulation(raw, "bench", Comm(), base_dir=str(ROOT))
    if err:
        sys.exit(err)
    return sim


def steps(scene, overrides):
    raw = yaml.safe_load(open(scene))
    for kv in overrides:
        key, value = kv.split("=", 1)
        if value == "DELETE":
            raw.pop(key, None)
        else:
            raw[key] = yaml.safe_load(value)
    sim = _sim(raw)
    comm = sim.comm
    for _ in range(5):
        sim.step()
    wall, cpu, its = np.inf, np.inf, []
    for _ in range(4):
        comm.synchronize()
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(20):
            its.append(sim.step()["ksp_iterations"])
        comm.synchronize()
        wall = min(wall, (time.perf_counter() - t0) / 20)
        cpu = min(cpu, (time.process_time() - c0) / 20)
    wall, cpu = comm.max(np.array([wall, cpu]))
    if comm.rank == 0:
        print(f"{1e3 * wall:.2f} ms/step wall, {1e3 * cpu:.2f} ms/step CPU, "
              f"{np.mean(its):.1f} CG its/step, {sim.system.describe()}")
    sim.destroy()


def tablecloth_state(path, n):
    sim = _sim(yaml.safe_load(open(TABLECLOTH)))
    for _ in range(n):
        sim.step()
    np.save(path, sim.state.x)
    sim.destroy()


def membrane(path):
    sim = _sim(yaml.safe_load(open(TABLECLOTH)))
    term = next(t for t in sim.terms if t.name == "force:membrane")
    for name, x in (("at rest", sim.state.x.copy()), ("saved state", np.load(path))):
        f = np.zeros_like(x)
        term.evaluate(x + 1.0, None, f, True)          # compile / warm caches elsewhere
        best = np.inf
        for _ in range(5):
            c0 = time.process_time()
            for k in range(10):
                # a new x each time: the term serves a repeat at the same x from memory
                term.evaluate(x + 1e-12 * (k + 1), None, f, True)
            best = min(best, (time.process_time() - c0) / 10)
        print(f"{name}: {1e3 * best:.2f} ms CPU per evaluation with Hessians "
              f"({term.tris.shape[0]} triangles)")
    sim.destroy()


def startup(path):
    import pstats
    st = pstats.Stats(path).stats

    def cum(part, func):
        return sum(v[3] for (f, _, fn), v in st.items() if part in f and fn == func)
    rows = [("total", max(v[3] for v in st.values())),
            ("imports of distcloth.cli", cum("distcloth/cli.py", "<module>")),
            ("  mpi4py.MPI (MPI_Init)", cum("distcloth/parallel/comm.py", "<module>")),
            ("  numba", cum("numba/__init__.py", "<module>")),
            ("  distcloth.lab", cum("distcloth/lab/__init__.py", "<module>")),
            ("  scipy.signal", cum("scipy/signal/__init__.py", "<module>")),
            ("  scene.animated_body", cum("distcloth/scene/animated_body.py", "<module>")),
            ("  h5py", cum("h5py/__init__.py", "<module>")),
            ("  scipy.sparse", cum("scipy/sparse/__init__.py", "<module>")),
            ("PETSc initialisation", cum("distcloth/linalg/petsc.py", "init_petsc")),
            ("scene read and check", cum("distcloth/config/load.py", "load_config")),
            ("model", cum("distcloth/scene/build.py", "build_model")),
            ("Simulation (METIS, terms, system)", cum("distcloth/simulation.py", "__init__")),
            ("prepare (first forces, solver set-up)", cum("distcloth/simulation.py", "prepare")),
            ("numba cache loads", cum("numba/core/caching.py", "load_overload")),
            ("opening the HDF5 result", cum("distcloth/run.py", "open_writer")),
            ("steps", cum("distcloth/simulation.py", "step"))]
    for name, seconds in rows:
        print(f"{name:45s} {seconds:6.3f} s")


def tablecloth_stage():
    sim = _sim(yaml.safe_load(open(TABLECLOTH)))
    sim.step()
    sim.pipeline.take_step_counters()
    acc = {"before": np.zeros(4), "after": np.zeros(4)}
    for step in range(2, 81):
        c0 = time.process_time()
        sim.step()
        cpu = time.process_time() - c0
        seconds, calls = sim.pipeline.take_step_counters()
        key = "before" if step <= 25 else "after" if step > 30 else None
        if key:
            acc[key] += (calls["force:membrane"], seconds["force:membrane"], cpu, 1)
    for key, (calls, wall, cpu, n) in acc.items():
        print(f"{key} contact: membrane {calls / n:.2f} calls/step, {1e3 * wall / n:.2f} ms/step "
              f"wall; whole step {1e3 * cpu / n:.1f} ms CPU")
    sim.destroy()


def profile(scene, n):
    import cProfile
    import pstats
    sim = _sim(yaml.safe_load(open(scene)))
    for _ in range(3):
        sim.step()
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(n):
        sim.step()
    prof.disable()
    if sim.comm.rank == 0:
        pstats.Stats(prof).sort_stats("tottime").print_stats(25)
    sim.destroy()


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    what, arg, rest = sys.argv[1], (sys.argv[2:] or [""])[0], sys.argv[3:]
    if what == "steps":
        steps(arg, rest)
    elif what == "membrane":
        membrane(arg)
    elif what == "tablecloth-state":
        tablecloth_state(arg, int(rest[0]) if rest else 80)
    elif what == "startup":
        startup(arg)
    elif what == "tablecloth-stage":
        tablecloth_stage()
    elif what == "profile":
        profile(arg, int(rest[0]) if rest else 100)
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
