#!/usr/bin/env python3
"""Measured orders of convergence of every integrator on a nonlinear oscillator,
with Newton converged (1e-10) and with one linearised Newton step per time step.

    .venv/bin/python scripts/convergence_orders.py

An elastic spring pendulum in 3D (k = 10 N/m, m = 0.1 kg, rest length 0.5 m,
gravity), integrated to T = 0.5 s with h = 0.02 / 2^i, i = 0..4; the error is
the final position against scipy's DOP853 at rtol 1e-13.  The test suite
checks the converged slopes (tests/test_integrators.py); this prints both.
"""
import sys

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))

from distcloth.config.load import config_from_dict  # noqa: E402
from distcloth.linalg.petsc import init_petsc  # noqa: E402
from distcloth.model import STRUCTURAL, Model  # noqa: E402

K, M, L0, T = 10.0, 0.1, 0.5, 0.5
G = np.array([0.0, 0.0, -9.81])
X0, V0 = np.array([0.3, 0.0, -0.45]), np.array([0.0, 0.5, 0.2])
ORDERS = {"backward_euler": 1, "bdf2": 2, "implicit_midpoint": 2, "newmark": 2,
          "symplectic_euler": 1, "explicit_midpoint": 2, "rk4": 4}
STEPS = [0.02 / 2 ** i for i in range(5)]


def model():
    m = Model(rest_positions=np.array([[0.0, 0, 0], [0, 0, -L0]]), triangles=np.zeros((0, 3), np.int64),
              vertex_mass=np.array([M, M]), vertex_area=np.zeros(2),
              spring_vertices=np.array([[0, 1]]), spring_rest_length=np.array([L0]),
              spring_stiffness=np.array([K]), spring_damping=np.zeros(1),
              spring_kind=np.array([STRUCTURAL], np.int8), pinned=np.array([0]))
    m.initial_positions = np.array([[0.0, 0, 0], X0])
    m.initial_velocities = np.array([[0.0, 0, 0], V0])
    return m


def final(integrator, h, newton):
    from distcloth.parallel.comm import Comm
    from distcloth.simulation import Simulation
    raw = {"cloth": [{"mesh": {"grid": {"size": [1, 1], "resolution": [2, 2]}}}],
           "effects": ["gravity", "membrane"],
           "time": {"end": T, "step": h, "integrator": integrator,
                    "newton_iterations": newton, "newton_tolerance": 1e-10},
           "solver": {"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"},
           "output": {"file": "unused.h5", "every": T, "preview": False}}
    sim = Simulation(config_from_dict(raw, ".", "orders"), model(), Comm(), quiet=True)
    sim.prepare()
    for _ in range(int(round(T / h))):
        sim.step()
    x = sim.state.x[sim.layout.owned_input.tolist().index(1)] if 1 in sim.layout.owned_input else None
    sim.destroy()
    return x


def main():
    init_petsc([])
    sol = solve_ivp(lambda t, y: np.concatenate([y[3:], -K / M * (np.linalg.norm(y[:3]) - L0)
                                                 * y[:3] / np.linalg.norm(y[:3]) + G]),
                    (0, T), np.concatenate([X0, V0]), method="DOP853", rtol=1e-13, atol=1e-15)
    ref = sol.y[:3, -1]
    print("| integrator | theory | slope, Newton converged | slope, one Newton step | error at h = 1.25 ms (converged / one step) |")
    print("|---|---:|---:|---:|---:|")
    for name, order in ORDERS.items():
        slopes, last = [], []
        for newton in (30, 1):
            err = np.array([np.linalg.norm(final(name, h, newton) - ref) for h in STEPS])
            slopes.append(np.polyfit(np.log(STEPS), np.log(err), 1)[0])
            last.append(err[-1])
        explicit = name in ("symplectic_euler", "explicit_midpoint", "rk4")
        one = "(explicit)" if explicit else f"{slopes[1]:.2f}"
        print(f"| {name} | {order} | {slopes[0]:.2f} | {one} | {last[0]:.2e} / {last[1]:.2e} |")


if __name__ == "__main__":
    main()
