"""The step's health checks and the diagnostics they rest on (all ranks in process).

* FE membrane energy and strain reach the diagnostics: a uniformly stretched
  sheet has the closed-form energy A E e^2 / 2 and the strain lambda - 1 for
  both strain measures (before, FE cloth reported 0 and ``time.max_strain``
  never fired);
* the energy guard stops a step that gains energy in a passive scene (one
  linearised backward-Euler step at 0.1 s overstretches a hanging sheet),
  names the step and the gain, is what stopped it (off, the run goes on),
  and with ``adaptive`` the halved steps keep the energy inside its bound;
* the guard waits for moving colliders to stop;
* the Newton retry of a step that gained energy stops once its iterate gains
  none, and no committed step then gains; a rejection after that early stop
  solves the step again to Newton's limit;
* an unconverged Newton loop is counted, and rejected on request.
"""
import numpy as np
import pytest

from distcloth.energy_guard import EnergyGuard
from distcloth.scene import build_model
from distcloth.config.load import config_from_dict

from test_physics import grid_scene, make_sim


def _stretched_fe_sheet(strain_model, lam, **time):
    raw = grid_scene(effects=["membrane", "bending"], time={"end": 1.0, "step": 0.02, **time})
    raw["cloth"][0]["material"] = {"model": "fem", "density": 0.1, "E_weft": 10.0,
                                   "E_warp": 10.0, "nu_weft": 0.0, "nu_warp": 0.0, "G": 2.0,
                                   "strain": strain_model, "bending": 1e-6}
    cfg = config_from_dict(raw, ".", "test")
    model = build_model(cfg)
    x = model.start_positions().astype(np.float64)
    c = x.mean(axis=0)
    model.initial_positions = c + (x - c) * np.array([lam, 1.0, 1.0])
    return make_sim(raw, model)


@pytest.mark.parametrize("strain_model", ["stvk", "corotated"])
def test_fe_membrane_energy_and_strain_reach_the_diagnostics(strain_model):
    lam, area, E = 1.05, 0.25, 10.0
    sim = _stretched_fe_sheet(strain_model, lam)
    kinetic, grav, elastic = sim.energies()
    # a flat sheet stretched uniformly along the weft: constant strain, no
    # bending; Green e = (lam^2 - 1)/2 (stvk), Biot e = lam - 1 (corotated)
    e = (lam * lam - 1) / 2 if strain_model == "stvk" else lam - 1
    assert kinetic == 0 and grav == 0
    assert elastic == pytest.approx(area * E * e * e / 2, rel=1e-10)
    # the step's strain is the principal stretch - 1 whatever the model's measure
    assert sim.comm.max(np.array([sim.max_strain()]))[0] == pytest.approx(lam - 1, rel=1e-10)
    sim.destroy()


def test_fe_strain_bound_now_rejects():
    from distcloth.simulation import SimulationError
    sim = _stretched_fe_sheet("stvk", 1.05, max_strain=0.01)
    with pytest.raises(SimulationError, match=r"step 1: strain 0\.0\d+ exceeds time.max_strain = 0.01"):
        sim.step()
    sim.destroy()


def _overstretching_scene(**time):
    # 9 x 9 hanging square, one linearised backward-Euler step of 0.1 s: the
    # first step throws the sheet far below its rest length (the stability
    # suite's large_step_0.1 case, where the energy rose by 0.5 S to 1e4 S);
    # without the Newton retry of a step that gains energy
    return _pinned(grid_scene(time={"end": 1.0, "step": 0.1, "energy_retry_newton": 1,
                                    **time}))


def _pinned(raw):
    raw["cloth"][0]["pins"] = [{"edge": "top"}]
    return raw


def _run(sim, steps):
    diags = []
    for _ in range(steps):
        diags.append(sim.step())
    return diags


def test_energy_guard_stops_a_passive_energy_gain_and_names_it():
    from distcloth.simulation import SimulationError
    sim = make_sim(_overstretching_scene())
    with pytest.raises(SimulationError, match=r"step \d+: energy gain: total energy [0-9.]+ S "
                                              r"above .*max_energy_gain = 0.1 S"):
        _run(sim, 10)
    sim.destroy()
    # the guard is what stopped it: switched off, the run goes to its end
    sim = make_sim(_overstretching_scene(energy_guard=False))
    diags = _run(sim, 10)
    assert max(d["total_energy"] for d in diags) > diags[0]["total_energy"]
    sim.destroy()


def test_energy_guard_with_adaptive_steps_keeps_the_bound():
    sim = make_sim(_overstretching_scene(adaptive=True, max_halvings=8))
    e_ref, scale = sim.state.energy_reference
    diags = _run(sim, 10)
    assert abs(sim.state.t - 1.0) < 1e-12
    assert diags[-1]["rejected_steps"] > 0
    assert min(d["step_size"] for d in diags) < 0.1
    # every committed state, halved or not, is inside the guard's bound
    assert max(d["total_energy"] for d in diags) <= e_ref + 0.1 * scale
    sim.destroy()


def test_the_newton_retry_runs_the_overstretching_scene_to_its_end():
    # the same steps with the default retry: the steps the guard or the step's
    # own energy test refuse are solved again with Newton and accepted, no
    # halving; every committed state within the guard's bound
    sim = make_sim(_overstretching_scene(energy_retry_newton=10))
    e_ref, scale = sim.state.energy_reference
    diags = _run(sim, 10)
    assert abs(sim.state.t - 1.0) < 1e-12 and diags[-1]["rejected_steps"] == 0
    assert sim.energy_retries > 0
    assert max(d["total_energy"] for d in diags) <= e_ref + 0.1 * scale
    sim.destroy()


def test_the_retry_stops_once_the_step_gains_no_energy():
    # the same retried steps, with Newton to convergence or stopped at the first
    # iterate that gains no energy (the default): the early stop must take fewer
    # Newton iterations, and every step it committed must end no higher than the
    # step before it (within STEP_GAIN_TOLERANCE * S, the test it stopped on);
    # backward Euler is dissipative, so a converged step could not either
    from distcloth.simulation import STEP_GAIN_TOLERANCE
    runs = {}
    for until in ("converged", "no_gain"):
        sim = make_sim(_overstretching_scene(energy_retry_newton=10, energy_retry_until=until))
        e_ref, scale = sim.state.energy_reference
        e0 = sum(sim.energies())
        diags = _run(sim, 10)
        assert abs(sim.state.t - 1.0) < 1e-12 and diags[-1]["rejected_steps"] == 0
        assert sim.energy_retries > 0
        energies = np.array([e0] + [d["total_energy"] for d in diags])
        assert np.all(energies <= e_ref + 0.1 * scale)
        runs[until] = (energies, np.array([d["newton_iterations"] for d in diags]), scale,
                       diags[-1]["newton_unconverged"])
        sim.destroy()
    energies, newton, scale, unconverged = runs["no_gain"]
    assert newton.sum() < runs["converged"][1].sum()
    assert unconverged > runs["converged"][3]        # the stopped steps are counted
    retried = np.flatnonzero(newton > 1)
    assert retried.size > 0
    assert np.all(np.diff(energies)[retried] <= STEP_GAIN_TOLERANCE * scale)


def test_a_rejection_after_an_early_stop_solves_the_step_to_the_limit():
    # the checks after the solve (contact response, strain limiting) can add
    # energy the stopped iterate did not have: the attempt is then rejected and
    # the step solved again with Newton to its limit, as the old rule does.  The
    # rejection is injected at the first early stop (a scene where a response
    # adds exactly that much is not at hand); up to that step both rules take
    # the same path, so the step must equal the converged rule's to round-off
    from distcloth.energy_guard import ENERGY_GAIN
    converged = make_sim(_overstretching_scene(energy_retry_newton=10,
                                               energy_retry_until="converged"))
    reference = _run(converged, 10)
    sim = make_sim(_overstretching_scene(energy_retry_newton=10, energy_retry_until="no_gain"))
    check, rejected = sim._check_state, []

    def rejecting_the_first_early_stop():
        reason, energies = check()
        if sim._retry_stopped and not rejected:
            rejected.append(sim.state.step)
            return f"{ENERGY_GAIN}: injected after the early stop", energies
        return reason, energies

    sim._check_state = rejecting_the_first_early_stop
    for _ in range(10):
        diag = sim.step()
        if rejected:
            break
    assert rejected == [sim.state.step]
    first = reference[sim.state.step - 1]
    assert diag["newton_iterations"] == first["newton_iterations"] > 1
    assert diag["rejected_steps"] == 0
    assert diag["newton_unconverged"] == first["newton_unconverged"]
    assert diag["total_energy"] == pytest.approx(first["total_energy"], rel=1e-12)
    converged.destroy()
    sim.destroy()


def test_guard_waits_for_moving_colliders():
    guard = EnergyGuard(0.1, drive_end=0.5, gravity_scale=1.0)
    assert not guard.wants_reference(0.0, None)
    assert guard.check(None, 0.0, 0.0, 1e6) is None    # work done by a moving body
    assert guard.wants_reference(0.5, None)
    reference = guard.reference(kinetic=2.0, gravitational=-1.0, elastic=0.5)   # S = 3.5
    assert reference == (1.5, 3.5)
    assert not guard.wants_reference(0.6, reference)   # taken once
    assert guard.check(reference, 2.0, -1.0, 0.5 + 0.34) is None
    assert "0.103 S above" in guard.check(reference, 2.0, -1.0, 0.5 + 0.36)
    assert EnergyGuard(None, 0.0, 1.0).wants_reference(0.0, None) is False   # off


def test_drive_end_is_the_last_collider_keyframe():
    raw = grid_scene(effects=["gravity", "membrane", "collisions"])
    raw["colliders"] = [{"shape": "sphere", "center": [0, 0, 0.5], "radius": 0.2,
                         "motion": {"times": [0.0, 0.3], "translations": [[0, 0, 0], [0, 0, 0.2]]}},
                        {"shape": "plane", "normal": [0, 0, 1], "offset": 0.0}]
    sim = make_sim(raw)
    assert sim.contact.drive_end == pytest.approx(0.3)
    assert sim.state.energy_reference is None            # not passive before 0.3 s
    _run(sim, 16)                                          # to 0.32 s
    assert sim.state.energy_reference is not None
    sim.destroy()


def test_unconverged_newton_is_counted_and_rejected_on_request():
    from distcloth.simulation import SimulationError
    # a hanging sheet (nonlinear springs); two Newton iterations cannot reach
    # 1e-30, below the linear solves' own 1e-12
    sim = make_sim(_pinned(grid_scene(time={"end": 0.1, "step": 0.02, "newton_iterations": 2,
                                            "newton_tolerance": 1e-30})))
    diags = _run(sim, 3)
    assert [d["newton_unconverged"] for d in diags] == [1, 2, 3]
    sim.destroy()
    sim = make_sim(_pinned(grid_scene(time={"end": 0.1, "step": 0.02, "newton_iterations": 2,
                                            "newton_tolerance": 1e-30,
                                            "require_newton_convergence": True})))
    with pytest.raises(SimulationError, match=r"step 1: Newton did not converge in 2 iterations"):
        sim.step()
    sim.destroy()
    # converged Newton is not counted
    sim = make_sim(_pinned(grid_scene(time={"end": 0.1, "step": 0.02, "newton_iterations": 20,
                                            "newton_tolerance": 1e-6})))
    assert _run(sim, 2)[-1]["newton_unconverged"] == 0
    sim.destroy()


# ------------------------------------------------------------ friction in the solve

def _one_contact(v, f_other, mu=0.5, m=0.01, h=0.005):
    """A friction term on one contact vertex of a floor (n = z, at rest), its
    coefficient from the start state, and the implicit velocity after one
    backward-Euler step of m dv = h (f_other + f_friction(v1)) (tangential part)."""
    from distcloth.collision.response import Contacts
    from distcloth.physics.contact_friction import ContactFrictionTerm
    term = ContactFrictionTerm(np.array([m]), 1)
    c = Contacts(index=np.array([0]), collider=np.array([0]), normal=np.array([[0.0, 0.0, 1.0]]),
                 velocity=np.zeros((1, 3)), phi=np.zeros(1), offset=np.ones(1) * 1e-3,
                 friction=np.array([mu]), target=np.zeros(1))
    term.begin_step(c, h)
    force = np.array([f_other], dtype=float)
    term.evaluate(None, np.array([v], dtype=float), force, True)
    cf = term.c[0]
    vt_star = (np.array(v) + h * np.array(f_other) / m)[:2]
    return vt_star / (1.0 + h * cf / m), vt_star


def test_friction_in_the_solve_is_exact_coulomb_for_one_vertex():
    m, h, mu, g = 0.01, 0.005, 0.5, 9.81
    weight = [0.0, 0.0, -m * g]
    # sliding at 1 m/s: the step removes exactly the kinetic impulse mu m g h
    v1, vs = _one_contact([1.0, 0.0, 0.0], weight, mu, m, h)
    assert v1[0] == pytest.approx(1.0 - mu * g * h, rel=1e-12)
    # pulled sideways by less than mu m g from rest: held (creep < 1e-4 m/s)
    v1, _ = _one_contact([0.0, 0.0, 0.0], [0.4 * m * g, 0.0, -m * g], mu, m, h)
    assert 0.0 <= v1[0] < 1e-4
    # pulled by more: slides with the net force (0.8 - 0.5) m g
    v1, _ = _one_contact([0.0, 0.0, 0.0], [0.8 * m * g, 0.0, -m * g], mu, m, h)
    assert v1[0] == pytest.approx((0.8 - mu) * g * h, rel=1e-12)
    # an approaching vertex presses harder: its impulse m v_n / h counts
    v1, _ = _one_contact([1.0, 0.0, -0.2], weight, mu, m, h)
    assert v1[0] == pytest.approx(1.0 - mu * (g * h + 0.2), rel=1e-12)
    # a vertex pulled away from the body is not pressed: no friction
    v1, _ = _one_contact([1.0, 0.0, 0.0], [0.0, 0.0, m * g], mu, m, h)
    assert v1[0] == pytest.approx(1.0, rel=1e-12)
