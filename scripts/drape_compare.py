#!/usr/bin/env python3
"""Iterations and time to drape Volino and Magnenat-Thalmann 2007's hanging
square, per relaxation method.

    scripts/mpiexec.sh 2 .venv/bin/python scripts/drape_compare.py [--resolution 41] [--tolerance 1e-3] \
        [--methods newton ...]

The cloth of Volino and Magnenat-Thalmann 2007, Fig. 4: a 50 cm square
hanging along one edge, 0.1 kg/m², 10 N/m, 20 ms steps, initially flat;
bending B = 1e-6 N·m (flexion springs).  Each method runs until every free
vertex's force is below tolerance × its weight.  Prints a Markdown table (rank 0).
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=int, default=41)
    ap.add_argument("--tolerance", type=float, default=1e-3)
    ap.add_argument("--max-iterations", type=int, default=5000)
    ap.add_argument("--methods", nargs="+", default=["stop_and_go", "dynamic", "quasistatic",
                                                     "newton"])
    args = ap.parse_args()
    from distcloth.linalg.petsc import init_petsc
    init_petsc([])
    from distcloth.config.load import config_from_dict
    from distcloth.integrate.drape import Relaxation, relax_to_rest
    from distcloth.parallel.comm import Comm
    from distcloth.scene import build_model
    from distcloth.simulation import Simulation
    comm = Comm()
    rows = []
    for method, stop_on in (("stop_and_go", "potential"), ("stop_and_go", "kinetic"),
                            ("dynamic", "potential"), ("quasistatic", "potential"),
                            ("newton", "potential")):
        if method not in args.methods:
            continue
        raw = {"cloth": [{"name": "square", "mesh": {"grid": {"size": [0.5, 0.5],
                          "resolution": [args.resolution] * 2}, "center": [0, 0, 1]},
                          "pins": [{"edge": "top"}],
                          "material": {"density": 0.1, "stretch": 10.0, "shear": 1.0, "bending": 1e-6}}],
               "effects": ["gravity", "membrane", "bending"],
               "time": {"end": 1000.0, "step": 0.02},
               "solver": {"ksp_rtol": 1e-8, "ksp_norm_type": "unpreconditioned"},
               "drape": {"method": method, "stop_on": stop_on, "tolerance": args.tolerance,
                         "max_iterations": args.max_iterations},
               "output": {"file": "unused.h5", "every": 1000.0, "preview": False}}
        cfg = config_from_dict(raw, ".", "drape")
        sim = Simulation(cfg, build_model(cfg), comm, quiet=True)
        sim.prepare()
        relax = Relaxation(sim, cfg.drape)
        k, d, ksp, _, wall = relax_to_rest(relax, args.max_iterations)
        rows.append((method + ("" if method != "stop_and_go" else f" ({stop_on})"), k,
                     relax.stops, ksp, wall, d["residual"], d["potential_energy"]))
        sim.destroy()
    if comm.rank == 0:
        print("| method | iterations | stops | CG iterations | wall s | residual | potential energy J |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]:.2f} | {r[5]:.2e} | {r[6]:.6f} |")


if __name__ == "__main__":
    main()
