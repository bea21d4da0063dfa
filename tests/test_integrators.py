"""Orders of convergence of every integrator on a nonlinear oscillator.

An elastic spring pendulum in 3D (one mass on a spring from a pinned anchor,
under gravity): nonlinear through the rotating spring direction.  The
reference is scipy's DOP853 at rtol 1e-13 on the same ODE, independent of
distcloth.  Newton is iterated to 1e-10 with ksp_rtol 1e-12 so that only the
discretisation error remains; five step sizes (four halvings).  The measured
slope of log(error) against log(h) must lie within 0.15 of the theoretical
order: at these steps (h omega <= 0.2) the schemes are near their asymptotic
range (measured slopes: backward Euler 0.91, still pre-asymptotic at the
largest step; BDF-2 1.94; implicit midpoint and Newmark 2.00; symplectic
Euler 1.01; explicit midpoint 1.98; RK4 3.98).
"""
import numpy as np
import pytest
from mpi4py import MPI
from scipy.integrate import solve_ivp

from distcloth.model import STRUCTURAL, Model
from test_physics import gather_positions, grid_scene, make_sim

K, M, L0, T = 10.0, 0.1, 0.5, 0.5
G = np.array([0.0, 0.0, -9.81])
X0 = np.array([0.3, 0.0, -0.45])
V0 = np.array([0.0, 0.5, 0.2])
ORDERS = {"backward_euler": 1, "bdf2": 2, "implicit_midpoint": 2, "newmark": 2,
          "symplectic_euler": 1, "explicit_midpoint": 2, "rk4": 4}
STEPS = [0.02 / 2 ** i for i in range(5)]
# every rank owns some of the cloth: the pendulum's two vertices take two at most
pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 2,
                                reason="the spring pendulum has two vertices: at most two ranks")


def pendulum_model():
    x = np.array([[0.0, 0.0, 0.0], X0])
    model = Model(rest_positions=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -L0]]),
                  triangles=np.zeros((0, 3), np.int64), vertex_mass=np.array([M, M]),
                  vertex_area=np.zeros(2), spring_vertices=np.array([[0, 1]]),
                  spring_rest_length=np.array([L0]), spring_stiffness=np.array([K]),
                  spring_damping=np.zeros(1), spring_kind=np.array([STRUCTURAL], np.int8),
                  pinned=np.array([0]))
    model.initial_positions = x
    model.initial_velocities = np.array([[0.0, 0.0, 0.0], V0])
    return model


def reference():
    def rhs(t, y):
        x, v = y[:3], y[3:]
        r = np.linalg.norm(x)
        return np.concatenate([v, -K / M * (r - L0) * x / r + G])
    sol = solve_ivp(rhs, (0.0, T), np.concatenate([X0, V0]), method="DOP853",
                    rtol=1e-13, atol=1e-15)
    return sol.y[:3, -1]


def final_position(integrator, h):
    raw = grid_scene(effects=["gravity", "membrane"],
                     time={"end": T, "step": h, "integrator": integrator,
                           "newton_iterations": 30, "newton_tolerance": 1e-10},
                     solver={"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"})
    sim = make_sim(raw, pendulum_model())
    for _ in range(int(round(T / h))):
        sim.step()
    x = gather_positions(sim)[1]
    sim.destroy()
    return x


@pytest.mark.parametrize("integrator", list(ORDERS))
def test_order_of_convergence(integrator):
    ref = reference()
    errors = np.array([np.linalg.norm(final_position(integrator, h) - ref) for h in STEPS])
    slope = np.polyfit(np.log(STEPS), np.log(errors), 1)[0]
    assert abs(slope - ORDERS[integrator]) <= 0.15, (slope, errors)


def energy_history(integrator, h=0.01, end=20.0):
    raw = grid_scene(effects=["gravity", "membrane"],
                     time={"end": end, "step": h, "integrator": integrator,
                           "newton_iterations": 30, "newton_tolerance": 1e-10},
                     solver={"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"})
    sim = make_sim(raw, pendulum_model())
    energy = [sim.step()["total_energy"] for _ in range(int(round(end / h)))]
    sim.destroy()
    return np.array(energy)


def test_energy_bounded_or_decaying():
    """Undamped, 2000 steps (about 30 periods): implicit midpoint and symplectic
    Euler keep the energy bounded (their errors oscillate, O(h^2) and O(h)),
    backward Euler dissipates it."""
    e0 = 0.5 * M * V0 @ V0 + 0.5 * K * (np.linalg.norm(X0) - L0) ** 2 - M * G @ X0
    scale = abs(e0)
    for name, bound in (("implicit_midpoint", 1e-3), ("symplectic_euler", 0.05)):
        e = energy_history(name)
        drift = np.abs(e - e0) / scale
        assert drift.max() <= bound, (name, drift.max())
        # bounded, not slowly growing: the last third oscillates like the first
        third = len(e) // 3
        assert drift[-third:].max() <= 1.5 * drift[:third].max() + 1e-9, name
    e = energy_history("backward_euler")
    # the oscillation energy decays (28 % of |E0| over the run) and never grows
    assert e[-1] < e0 - 0.05 * scale and np.all(np.diff(e[::50]) <= 1e-9 * scale)
