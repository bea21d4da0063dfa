#!/usr/bin/env python3
"""Errors and observed orders of an implicit scheme on the stiff hanging square S1
(0.5 m, edge x = 0 pinned, 0.1 kg/m^2, FE membrane 1000 N/m, bending 1e-6 N m,
gravity), one rank, against the same scheme at --ref-step with Newton converged.

    .venv/bin/python scripts/integrator_orders_s1.py --n 21 --ref-newton 30 \
        --ref-time '{"newton_tolerance": 1e-9}' [--newton K] [--linearise-at-start]

Error: RMS vertex distance at the output times (TIMES=0.5,1,1.5,2 by default,
an environment variable), then RMS over the times; orders log2(e(h)/e(h/2)).
The reference is cached under /tmp/steps/.  docs/integrators.md, "Stiff
membranes", has the figures.

    .venv/bin/python scripts/integrator_orders_s1.py --n 41 --large-steps 0.02,0.0333333333

runs backward Euler and BDF-2 at those steps over the 2 s with the energy
guard on and no halving, with the retry (time.energy_retry_newton 10) and
without (1): how far each gets, the highest energy above the start (in S),
Newton iterations and wall time per step.
"""
import zlib, argparse, json, os, sys, time
import numpy as np
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
from distcloth.inprocess import build_simulation
from distcloth.linalg.petsc import init_petsc
from distcloth.parallel.comm import Comm

TIMES = tuple(float(t) for t in os.environ.get("TIMES", "0.5,1,1.5,2").split(","))


def scene(n, h, integ, newton=None, rtol=1e-3, guard=True, extra_time=None):
    t = {"end": max(TIMES), "step": h, "integrator": integ, "energy_guard": guard}
    if newton is not None:
        t["newton_iterations"] = newton
    t.update(extra_time or {})
    return {"scene": "s1",
            "cloth": [{"name": "square",
                       "mesh": {"grid": {"size": [0.5, 0.5], "resolution": [n, n]},
                                "center": [0.25, 0.0, 0.0]},
                       "pins": [{"box": {"min": [-1e-3, -1, -1], "max": [1e-3, 1, 1]}}],
                       "material": {"model": "fem", "density": 0.1, "stretch": 1000.0,
                                    "bending": 1e-6}}],
            "effects": ["gravity", "membrane", "bending"],
            "time": t,
            "solver": {"ksp_rtol": rtol},
            "output": {"file": "/tmp/steps/unused.h5", "every": 0.5, "preview": False}}


def run(raw, comm):
    sim, note, err = build_simulation(raw, "s1", comm)
    assert err is None, err
    h = raw["time"]["step"]
    order = np.argsort(sim.layout.owned_input)
    out, t0, its, kits = [], time.perf_counter(), 0, 0
    nsteps = int(round(max(TIMES) / h))
    marks = {int(round(t / h)) for t in TIMES}
    for k in range(1, nsteps + 1):
        d = sim.step()
        its += d["newton_iterations"]; kits += d["ksp_iterations"]
        if k in marks:
            out.append(sim.state.x[: sim.n_owned][order].copy())
    wall = time.perf_counter() - t0
    sim.destroy()
    return np.array(out), wall, its / nsteps, kits / nsteps


def large_steps(a, comm):
    print("| integrator | h (ms) | retry | linearised at | end | max E - E0 (S) | Newton its / step | ms / step |")
    print("|---|---:|---|---|---|---:|---:|---:|")
    for integ in ("backward_euler", "bdf2"):
        for h in map(float, a.large_steps.split(",")):
            for retry in (10, 1):
                raw = scene(a.n, h, integ, a.newton, a.rtol, extra_time={"energy_retry_newton": retry})
                sim, _, err = build_simulation(raw, "s1", comm)
                assert err is None, err
                e0, emax, its, end = sim.state.energy_reference, -np.inf, 0, "completed"
                t0 = time.perf_counter()
                try:
                    for _ in range(int(round(max(TIMES) / h))):
                        d = sim.step()
                        its += d["newton_iterations"]
                        emax = max(emax, (d["total_energy"] - e0[0]) / e0[1])
                except Exception as exc:        # the guard's stop: reported, not raised
                    end = f"stopped at step {sim.state.step}: {str(exc).split(':')[1].strip()}"
                steps = max(sim.state.step, 1)
                wall = (time.perf_counter() - t0) / steps * 1e3
                sim.destroy()
                where = "x0" if a.linearise_at_start else "predictor"
                print(f"| {integ} | {h * 1e3:.3g} | {retry} | {where} | {end} | {emax:.3g} | "
                      f"{its / steps:.2f} | {wall:.0f} |", flush=True)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, default=41)
    p.add_argument("--integrator", default="bdf2")
    p.add_argument("--steps", default="0.01,0.005,0.0025")
    p.add_argument("--newton", type=int, default=None)
    p.add_argument("--rtol", type=float, default=1e-3)
    p.add_argument("--ref-step", type=float, default=0.001)
    p.add_argument("--ref-newton", type=int, default=None)
    p.add_argument("--ref-integrator", default="bdf2")
    p.add_argument("--time", default="{}")
    p.add_argument("--ref-time", default="{}")
    p.add_argument("--large-steps", default=None, metavar="H1,H2",
                   help="the large-step table at these steps instead of the orders")
    p.add_argument("--linearise-at-start", action="store_true",
                   help="linearise at the start state (the former default), the reference too")
    a = p.parse_args()
    init_petsc([])
    if a.linearise_at_start:
        from distcloth.integrate.implicit import ImplicitScheme
        ImplicitScheme.linearise_at_predictor = lambda self: False
    comm = Comm()
    if a.large_steps:
        return large_steps(a, comm)
    os.makedirs("/tmp/steps", exist_ok=True)
    ref_file = f"/tmp/steps/refb{max(TIMES)}_{a.n}_{a.ref_integrator}_{a.ref_step}_{a.ref_newton}_{zlib.crc32(a.ref_time.encode())%10000}{'_x0' * a.linearise_at_start}.npy"
    if os.path.exists(ref_file):
        ref = np.load(ref_file)
    else:
        ref, wall, _, _ = run(scene(a.n, a.ref_step, a.ref_integrator, a.ref_newton, 1e-8,
                                     extra_time=json.loads(a.ref_time)), comm)
        np.save(ref_file, ref)
        print(f"reference {wall:.1f} s")
    errs = []
    for h in map(float, a.steps.split(",")):
        x, wall, its, kits = run(scene(a.n, h, a.integrator, a.newton, a.rtol,
                                       extra_time=json.loads(a.time)), comm)
        e = np.sqrt(np.mean(np.sum((x - ref) ** 2, axis=2), axis=1))
        errs.append(np.sqrt(np.mean(e ** 2)))
        print(f"h={h*1e3:g} ms err/time(mm)={np.round(e*1e3,2)} rms={errs[-1]*1e3:.2f} mm "
              f"wall={wall:.1f}s newton={its:.2f} ksp={kits:.1f}", flush=True)
    errs = np.array(errs)
    print("orders", np.round(np.log2(errs[:-1] / errs[1:]), 2))


if __name__ == "__main__":
    main()
