"""Friction over a convex edge: a strip slides over the kink between two
inclined faces at the speed Coulomb's law predicts, and sticks below the
friction angle.

The body.  Two analytic boxes (0.5 m x 0.2 m x 0.2 m half extents), each held
in a rotated pose by a one-keyframe rigid motion (rotation vector
[0, theta, 0]: the box's +x axis tilts to (cos theta, 0, -sin theta),
downhill in +x), with their top faces through the origin: the upper box's
top face (slope theta1) ends at the origin, the lower box's (slope theta2 >
theta1) starts there.  Their union has a convex edge of turning angle
dtheta = theta2 - theta1 along y through the origin, and each box's end
face lies inside the other box (checked below), so the cloth meets only the
two top faces and the edge.

The prediction.  An inextensible chain of mass per length lambda and length
L, a length s of it already past the kink, Coulomb friction mu on both faces
and capstan friction at the kink.  With G_i = g (sin theta_i - mu cos theta_i)
and T1, T2 the tension just above and just below the kink:

    upper part:  lambda (L - s) a = lambda (L - s) G1 + T1
    lower part:  lambda s a       = lambda s G2 - T2
    capstan, sliding towards the lower face:  T2 = e T1,  e = exp(mu dtheta)

so  a = s'' = (s G2 + e (L - s) G1) / (s + e (L - s)),  s(0) = s'(0) = 0,
integrated numerically (scipy's solve_ivp, rtol 1e-10).  The strip
(0.3 m x 0.06 m, FE membrane 1000 N/m: strains of order 1e-4, so it is
inextensible for this purpose; bending 1e-6 N m; thickness 1 mm; 61 x 7
vertices) starts at rest on the upper face with its front on the edge.  Its
path coordinate s is the rear edge's displacement along the upper face (the
rear stays on that face until s = L).  At mu = 0.15, theta1 = 12 deg,
theta2 = 30 deg it must reach s = L/2 (about 0.61 s) within 5 % of the
predicted time, moving within 5 % of the predicted speed there.

What the chain model leaves out, measured on this scene (2 ranks, friction
in the solve with its coefficient capped at mu N / max(|v_t| - mu N h / m,
V_STICK), physics/contact_friction.py):

* lift-off: to follow a kink a chain needs T1 >= lambda v^2 there; here that
  fails from s = 9 cm on and the strip (as a real one would) leaves the edge
  and lands on the lower face a few centimetres on (about 100 of 793
  vertices off the surface at s = L/2 on a 61 x 13 grid), losing the
  friction of the airborne part and some energy in the landing.  With
  mu = 0 the speed at s = L/2 is 2.0 % below the frictionless chain's and
  the arrival 1.1 % late, on 5 mm and 2.5 mm grids alike;
* the grid and the step: at mu = 0.15 the speed at s = L/2 is 1.6 % below
  the prediction and the arrival 1.4 % late on this test's grid (61 x 7,
  h = 2 ms); on 61 x 13 1.5 % and 1.4 % (h = 2 ms), 2.6 % and 1.7 %
  (h = 1 ms: more of the friction at the kink is resolved, less lift-off);
  on 121 x 25 (2.5 mm) 0.3 % and 0.5 %;
* bending: 1e-7 N m instead of 1e-6 changes the speed by 0.2 %, 1e-5 N m
  by 1.3 %.

Without that cap a contact
vertex at the kink is classed as held from an explicit estimate of its free
velocity (the bending and membrane forces of the kink nearly cancel it
within one step) and gets a damping coefficient for a held vertex while the
strip drags it at 0.15 m/s: friction forces of up to 1500 mu N in single
steps, and the strip loses up to a quarter of its speed each time.  On this
test's grid it reaches s = L/2 6.7 % late and 5.7 % slower than predicted,
the same on 1, 2 and 3 ranks (13 % and 9 % on 61 x 13).
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from test_physics import gather_positions, grid_scene, make_sim

G = 9.81
L, WIDTH = 0.3, 0.06            # m: the strip
NU, NV = 61, 7                  # vertices along and across (5 mm, 10 mm)
THICKNESS = 0.001               # m: d, the boxes have no thickness of their own
DENSITY = 0.2                   # kg/m^2: lambda = 0.012 kg/m
HALF = (0.5, 0.2, 0.2)          # m: half extents of each box


def downhill(theta):
    """Unit vector down a face of slope theta (rad) in the x-z plane."""
    return np.array([math.cos(theta), 0.0, -math.sin(theta)])


def face_normal(theta):
    return np.array([math.sin(theta), 0.0, math.cos(theta)])


def edge_scene(theta1_deg, theta2_deg, mu, h, overhang=0.0):
    """The strip on the upper face with its front ``overhang`` past the edge
    (lying straight along the upper face's direction), and the two boxes."""
    th1, th2 = math.radians(theta1_deg), math.radians(theta2_deg)
    a, b, c = HALF

    def box(name, x_center, theta):
        # the body frame's top face z = 0 passes through the origin; its end
        # face x = 0 is the edge's side
        return {"name": name, "shape": "box", "center": [x_center, 0.0, -c],
                "half_extents": [a, b, c], "friction": mu,
                "motion": {"times": [0.0], "rotations": [[0.0, theta, 0.0]]}}

    center = (overhang - 0.5 * L) * downhill(th1) + THICKNESS * face_normal(th1)
    return grid_scene(
        cloth=[{"name": "strip",
                "mesh": {"grid": {"size": [L, WIDTH], "resolution": [NU, NV]},
                         "center": center.tolist(), "rotation": [0.0, theta1_deg, 0.0]},
                "material": {"model": "fem", "density": DENSITY, "stretch": 1000.0,
                             "bending": 1e-6},
                "thickness": THICKNESS}],
        effects=["gravity", "membrane", "bending", "collisions"],
        colliders=[box("upper", -a, th1), box("lower", a, th2)],
        time={"end": 10.0, "step": h})


def chain_prediction(theta1_deg, theta2_deg, mu, t_end):
    """solve_ivp solution of the chain model (module docstring): y = (s, s')."""
    th1, th2 = math.radians(theta1_deg), math.radians(theta2_deg)
    g1 = G * (math.sin(th1) - mu * math.cos(th1))
    g2 = G * (math.sin(th2) - mu * math.cos(th2))
    e = math.exp(mu * (th2 - th1))

    def rhs(_, y):
        s = min(max(y[0], 0.0), L)
        return [y[1], (s * g2 + e * (L - s) * g1) / (s + e * (L - s))]

    return solve_ivp(rhs, (0.0, t_end), [0.0, 0.0], dense_output=True, rtol=1e-10,
                     atol=1e-12, max_step=1e-3)


def crossing(t, s, level):
    """Time at which the increasing-on-average sequence s first reaches level."""
    k = int(np.argmax(s >= level))
    return t[k - 1] + (level - s[k - 1]) * (t[k] - t[k - 1]) / (s[k] - s[k - 1])


def rear_path(sim, theta1_deg, steps, stop_at=None):
    """(t, s): the rear edge's displacement along the upper face after each step;
    stops early once s passes ``stop_at``."""
    t1 = downhill(math.radians(theta1_deg))
    rear0 = gather_positions(sim).reshape(NV, NU, 3)[:, 0].mean(axis=0)
    t, s = [0.0], [0.0]
    for _ in range(steps):
        sim.step()
        rear = gather_positions(sim).reshape(NV, NU, 3)[:, 0].mean(axis=0)
        t.append(sim.state.t)
        s.append(float((rear - rear0) @ t1))
        if stop_at is not None and s[-1] > stop_at:
            break
    return np.array(t), np.array(s)


def test_box_end_faces_are_hidden_inside_the_other_box():
    # the union of the two boxes has only the two top faces and the edge near
    # the cloth: every point of one box's end face (below the edge) is inside
    # the other box
    sim = make_sim(edge_scene(12.0, 30.0, 0.15, 0.002))
    upper, lower = (c.body for c in sim.contact.colliders)
    a, b, c = HALF
    # the side faces y = +-b are shared by both boxes: stay inside them
    y, depth = np.meshgrid(np.linspace(-0.9 * b, 0.9 * b, 9), np.linspace(1e-3, 2 * c, 40))
    for this, other, theta in ((upper, lower, 12.0), (lower, upper, 30.0)):
        th = math.radians(theta)
        # the end face x = 0 of the body frame: from the edge down along -z
        pts = (np.outer(depth.ravel(), -face_normal(th))
               + np.outer(y.ravel(), [0.0, 1.0, 0.0]))
        phi_this, _ = this.signed_distance(pts)
        phi_other, _ = other.signed_distance(pts)
        assert np.abs(phi_this).max() < 1e-12       # the points are on this box's end face
        assert phi_other.max() < 0.0, phi_other.max()


def test_strip_slides_over_convex_edge_at_coulomb_speed():
    theta1, theta2, mu, h = 12.0, 30.0, 0.15, 0.002
    sol = chain_prediction(theta1, theta2, mu, 2.0)
    t_pred = crossing(sol.t, sol.y[0], 0.5 * L)
    v_pred = float(sol.sol(t_pred)[1])
    sim = make_sim(edge_scene(theta1, theta2, mu, h))
    # run until the rear has moved 55 % of L (about 0.65 s), at most 1.3 t_pred
    t, s = rear_path(sim, theta1, int(1.3 * t_pred / h), stop_at=0.55 * L)
    assert s[-1] > 0.5 * L, f"after {t[-1]:.2f} s the strip moved only {s[-1]:.3f} m " \
                            f"(predicted L/2 = {0.5 * L} m at {t_pred:.3f} s)"
    t_half = crossing(t, s, 0.5 * L)
    # the speed there: slope of a quadratic fitted to s(t) over +-20 ms (the
    # rear edge vibrates slightly each time a grid column passes the kink)
    near = np.abs(t - t_half) <= 0.02
    v_half = float(np.polyval(np.polyder(np.polyfit(t[near] - t_half, s[near], 2)), 0.0))
    # 5 % (asked), against the measured floor of the discretisation: 2.0 %
    # slower from the lift-off and the discrete turn over the kink (mu = 0),
    # 1.6 % slower and 1.4 % later at this grid and step once friction keeps
    # to mu N at the kink (module docstring)
    assert abs(v_half - v_pred) <= 0.05 * v_pred, (v_half, v_pred, t_half, t_pred)
    assert abs(t_half - t_pred) <= 0.05 * t_pred, (t_half, t_pred, v_half, v_pred)


@pytest.mark.parametrize("overhang", [0.0, 0.5 * L], ids=["front_at_edge", "draped_half_over"])
def test_strip_sticks_at_convex_edge_below_friction_angle(overhang):
    # mu = 0.4: tan 12 deg = 0.21 and tan 18 deg = 0.32 are both below mu, so
    # G1, G2 < 0 and the chain model has no motion for any s.  With half the
    # strip over the edge it first falls 1.6 cm onto the lower face and drapes
    # over the edge, which must then hold it.
    theta1, theta2, mu, h = 12.0, 18.0, 0.4, 0.005
    sim = make_sim(edge_scene(theta1, theta2, mu, h, overhang=overhang))
    _, s = rear_path(sim, theta1, int(round(1.0 / h)))
    # 1 mm over 1 s (asked).  Static friction is regularised: a held vertex
    # creeps at up to V_STICK = 0.1 mm/s (physics/contact_friction.py);
    # measured 0.10 mm after 1 s with the front at the edge, 0.32 mm with half
    # the strip draped over the edge (a steady creep of 0.36 mm/s once draped)
    assert np.abs(s).max() < 1e-3, np.abs(s).max()
