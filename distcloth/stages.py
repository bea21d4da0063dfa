"""The step, declared once: its stages in the order they run.

Everything that lists stages is generated from ``STEP_STAGES``: the
pipeline's switches, counters and timers (distcloth/pipeline.py), the
stage datasets of the result file, the log's stage table, the stage table
of docs/architecture.md and the README's description of a step
(``python -m distcloth.stages --write`` regenerates both; a test fails when
they are stale).  Adding an effect means adding its stage here (with the
builder of its force term, for a force) and its key in the scene schema.

A step of size h from the committed state (x, v) at time t:

* ``kinematics`` .. ``constraints`` set up the attempt;
* the force stages, ``assembly`` and ``solve`` run inside the integrator,
  as often as it needs them (once per Newton iteration, four times per RK4
  step); with body contacts the attempt is solved again while the contact
  set changes (a contact turned adhesive, a free vertex ended inside a
  body), loosely until the set settles and then once more at the scene's
  tolerance, at most four passes (five when the first ones are loose);
* ``strain_limiting``, ``collision:response`` and ``update`` finish the attempt; the state is
  then checked (NaN, speed, strain, energy) and committed or restored;
* ``diagnostics`` and ``output`` report the committed step.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .physics.loads import build_loads
from .physics.sewing import build_seams, build_sewing
from .physics.terms import build_bending, build_damping, build_drag, build_gravity, build_membrane


@dataclass(frozen=True)
class Stage:
    name: str
    when: str          # when the stage exists / is switched on
    reads: str
    writes: str
    doc: str
    effect: str | None = None                 # the scene effect that turns it on (None: the
    #                                           model alone decides, by what build returns)
    build: Callable | None = None             # force stages: (cfg, model, layout) -> term


STEP_STAGES: tuple[Stage, ...] = (
    Stage("kinematics", "always", "held vertices, t, the integrator's position update",
          "target velocities of held vertices; time-dependent forces at the end of the step",
          "velocities that put pinned and sliding-pinned vertices where their grip's path "
          "(at rest, or a prescribed motion) is at the end of the step"),
    Stage("collision:bodies", "colliders and the collisions effect",
          "x, v, colliders at t, contacts the attempt released or missed", "contacts",
          "vertices predicted to end a step of free flight within the contact distance of a "
          "body, or of the garments worn under theirs, become unilateral contacts (with "
          "contact.model barrier: only the time at which the barrier sees the bodies)"),
    Stage("constraints", "always", "held vertices, contacts, v", "constraints (S, z)",
          "pins, sliding pins and contacts as per-vertex projections S and velocity changes z"),
    Stage("force:gravity", "effect gravity", "vertex masses", "forces",
          "weight m g", effect="gravity", build=build_gravity),
    Stage("force:loads", "effect loads", "t", "forces",
          "point and line loads on selected vertices, ramped from zero over their ramp time",
          effect="loads", build=build_loads),
    Stage("force:membrane", "effect membrane", "x", "forces, stiffness blocks",
          "in-plane elasticity: structural and shear springs, or FE triangles",
          effect="membrane", build=build_membrane),
    Stage("force:seams", "effect membrane on a welded garment", "x", "forces, stiffness blocks",
          "the seam lines of a sewn garment: springs along its seams, shorter than the fabric "
          "they join by the seam shrinkage", effect="membrane", build=build_seams),
    Stage("force:bending", "effect bending", "x", "forces, stiffness blocks",
          "mass-spring: flexion line elements (grids), hinges (mesh files), flexion springs "
          "(garment panels); fem: line and twist elements (grids), hinge or shell bending",
          effect="bending", build=build_bending),
    Stage("force:sewing", "a garment whose stitches are not yet welded", "x, t",
          "forces, stiffness blocks", "stitch springs whose rest length goes from the start gap "
          "to zero over the sewing duration", build=build_sewing),
    Stage("force:damping", "effect damping", "x, v", "forces, damping blocks",
          "damping along the springs", effect="damping", build=build_damping),
    Stage("force:drag", "effect drag with drag > 0", "v", "forces, damping blocks",
          "linear air drag", effect="drag", build=build_drag),
    Stage("force:friction", "an implicit integrator and a collider with friction",
          "contacts, v, the other forces at the start state", "forces, damping blocks",
          "Coulomb friction of body contacts as a force of the solve"),
    Stage("force:contact", "contact.model barrier, an implicit integrator and colliders",
          "x, v, colliders at the end of the step", "forces, stiffness and damping blocks",
          "the barrier energy of each vertex's gap to the bodies and its lagged friction, "
          "inside the step's Newton solve"),
    Stage("assembly", "implicit integrators", "stiffness and damping blocks, masses",
          "block values of A = M - beta df/dv - alpha df/dx",
          "the owned rows' 3x3 blocks in the pattern built once"),
    Stage("solve", "implicit integrators", "A, right-hand side, constraints",
          "velocity change", "pre-filtered CG (or any PETSc KSP) on the constrained system"),
    Stage("strain_limiting", "effect strain_limiting", "proposed x, v; contacts; pins",
          "proposed x, v", "Provot's position correction or the velocity directional "
          "modification of over-stretched springs, Jacobi passes with ghost exchanges",
          effect="strain_limiting"),
    Stage("collision:response", "colliders or self_collision",
          "proposed x, v; contacts; start forces; constraint impulses",
          "proposed x, v; the work of contacts, friction, fail-safe, impulses",
          "after-step friction, the position fail-safe and the triangle-contact pipeline"),
    Stage("update", "always", "proposed x, v", "x, v (owned rows, then ghosts)",
          "the proposed state becomes the state, ghosts refreshed"),
    Stage("diagnostics", "always", "committed state", "the step's diagnostics row",
          "energies, strain, speed, solver and contact counts"),
    Stage("output", "every output interval", "x, v, touching", "a frame in the result file",
          "collective HDF5 write of the positions and the per-frame fields"),
)

STAGES = tuple(s.name for s in STEP_STAGES)
FORCE_STAGES = tuple(s.name for s in STEP_STAGES if s.name.startswith("force:"))
BY_NAME = {s.name: s for s in STEP_STAGES}

ROOT = Path(__file__).resolve().parents[1]
MARK_BEGIN = "<!-- stage list: generated by python -m distcloth.stages; do not edit -->"
MARK_END = "<!-- end of stage list -->"


def stage_table() -> str:
    """The Markdown table of docs/architecture.md."""
    rows = ["| stage | runs when | reads | writes | what it does |", "|---|---|---|---|---|"]
    rows += [f"| `{s.name}` | {s.when} | {s.reads} | {s.writes} | {s.doc} |" for s in STEP_STAGES]
    return "\n".join(rows)


def stage_sentence() -> str:
    """The README's one-paragraph description of a step."""
    return ("The step is a pipeline of named stages, run in this order: "
            + ", ".join(f"`{s.name}`" for s in STEP_STAGES)
            + ". Each has a switch, a call counter and a timer; effects a scene does not "
              "name are never called, and the force stages, `assembly` and `solve` run "
              "inside the integrator as often as it needs them.")


GENERATED = {"docs/architecture.md": stage_table, "README.md": stage_sentence}


def regenerate(text: str, body: str) -> str:
    """``text`` with the part between the markers replaced by ``body``."""
    head, sep, rest = text.partition(MARK_BEGIN)
    _, sep2, tail = rest.partition(MARK_END)
    if not sep or not sep2:
        raise ValueError("the stage-list markers are missing")
    return f"{head}{MARK_BEGIN}\n{body}\n{MARK_END}{tail}"


def stale_files() -> list[str]:
    """The generated documents whose stage list is out of date."""
    out = []
    for name, make in GENERATED.items():
        text = (ROOT / name).read_text(encoding="utf-8")
        if regenerate(text, make()) != text:
            out.append(name)
    return out


def main(argv: list[str]) -> int:
    if "--write" in argv:
        for name, make in GENERATED.items():
            path = ROOT / name
            path.write_text(regenerate(path.read_text(encoding="utf-8"), make()), encoding="utf-8")
        return 0
    stale = stale_files()
    for name in stale:
        print(f"{name}: stage list out of date (python -m distcloth.stages --write)")
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
