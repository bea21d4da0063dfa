"""The barrier Newton's merit, the step's incremental potential
(integrate/implicit.py), has the residual it descends as its gradient:
its slope along any direction is the forces' work along it.  Checked with
spring damping, whose dissipation potential depends on the positions too,
lagged at the point where the forces are evaluated and at another one (the
step's first iterate, where the barrier Newton lags it for the whole step)."""
import numpy as np

from test_physics import grid_scene, make_sim


def _slopes(sim, h):
    """(central difference of the merit's potential part along w with the
    dissipation lagged at x, the same unlagged, -h f . w) for backward
    Euler's weights (a_x = h, a_v = 1, s = h) at random velocities."""
    ctx = sim.ctx
    n = ctx.n_owned
    rng = np.random.default_rng(7 + sim.comm.rank)
    x = sim.state.x.copy()
    v = np.zeros_like(x)
    v[:n] = rng.normal(scale=2.0, size=(n, 3))       # m/s: a shaken sheet
    w = np.zeros_like(x)
    w[:n] = rng.normal(size=(n, 3))
    ctx.update_ghosts(v, w)
    e = 1e-5

    def phi(eps, lagged):
        return ctx.potential(x + eps * h * w, v + eps * w, 1.0, h,
                             dissipation_at=x if lagged else None)

    lagged = (phi(e, True) - phi(-e, True)) / (2 * e)
    unlagged = (phi(e, False) - phi(-e, False)) / (2 * e)
    f = ctx.forces(x, v, want_jac=False)
    work = -h * float(ctx.global_sum(float(np.sum(f[:n] * w[:n])))[0])
    return lagged, unlagged, work


def _damped_sheet():
    raw = grid_scene(effects=["membrane", "bending", "damping"])
    raw["cloth"][0]["material"]["damping"] = 0.05
    raw["cloth"][0]["mesh"]["grid"]["resolution"] = [17, 17]
    return make_sim(raw)


def test_the_merit_s_slope_is_the_forces_work_with_the_dissipation_lagged():
    sim = _damped_sheet()
    try:
        lagged, unlagged, work = _slopes(sim, 0.02)
    finally:
        sim.destroy()
    # central differences of a smooth potential at e = 1e-5: truncation
    # ~1e-10 and round-off ~1e-16 |Phi| / e relative, far below 1e-6
    assert abs(lagged - work) <= 1e-6 * abs(work), (lagged, work)
    # with the trial positions in R the slope is another one: spring
    # directions turn at |v| h / l ~ 1.3 of a spring length here
    assert abs(unlagged - work) > 0.1 * abs(work), (unlagged, work)


def test_the_forces_with_lagged_damping_are_the_lagged_merit_s_gradient():
    sim = _damped_sheet()
    try:
        ctx = sim.ctx
        n = ctx.n_owned
        h = 0.02
        rng = np.random.default_rng(11 + sim.comm.rank)
        x = sim.state.x.copy()
        lag = x.copy()
        lag[:n] += rng.normal(scale=0.01, size=(n, 3))   # another iterate: 1 cm away
        v = np.zeros_like(x)
        v[:n] = rng.normal(scale=2.0, size=(n, 3))
        w = np.zeros_like(x)
        w[:n] = rng.normal(size=(n, 3))
        ctx.update_ghosts(lag, v, w)
        e = 1e-5

        def phi(eps):
            return ctx.potential(x + eps * h * w, v + eps * w, 1.0, h, dissipation_at=lag)

        slope = (phi(e) - phi(-e)) / (2 * e)

        def work(**kw):
            f = ctx.forces(x, v, want_jac=False, **kw)
            return -h * float(ctx.global_sum(float(np.sum(f[:n] * w[:n])))[0])

        lagged, own = work(dissipation_at=lag), work()
    finally:
        sim.destroy()
    # central differences as in the test above: 1e-6 relative is far above
    # their error
    assert abs(slope - lagged) <= 1e-6 * abs(lagged), (slope, lagged)
    # springs of 3 cm whose ends are 1 cm off turn the damping's force by
    # tens of degrees: the work differs by ~16 % on one rank; a lag that
    # did not reach the damping stage would make the two equal
    assert abs(own - lagged) > 0.05 * abs(lagged), (own, lagged)
