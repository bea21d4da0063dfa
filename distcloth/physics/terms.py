"""Force terms: one object per effect, each a stage of the step.

A term sees local arrays (owned vertices first, then ghosts) and never a
communicator.  Its contract:

* ``stencils()``: element vertex lists whose blocks it writes, fixed for the
  run, from which the matrix sparsity is built once;
* ``bind(pattern)``: remember where its blocks go in the value array;
* ``evaluate(x, v, force, want_jac)``: add its forces to ``force`` and keep
  what the Jacobian needs; returns {"elastic_energy": .., "max_strain": ..}
  contributions (energies already weighted so ranks sum to the total);
* ``stiffness_product(w, out)``: out += (df/dx) w at the last evaluation;
* ``add_to_system(data, alpha, beta)``: add its part of
  A = M - beta df/dv - alpha df/dx to the block values;
* ``energy(x)``: its potential energy only (diagnostics; 0 for dissipative
  terms);
* ``max_strain(x)``: its largest engineering strain (stretch - 1) at x, 0 for
  terms that do not stretch the membrane (diagnostics and ``time.max_strain``).

Adding an effect means adding a term here and naming it in ``build_terms``.
"""
from __future__ import annotations

import numpy as np

from ..model import FLEXION, SHEAR, STRUCTURAL
from . import springs as sk


class ForceTerm:
    name = "force"
    has_jacobian = True

    def stencils(self):
        return []

    def bind(self, pattern):
        pass

    def evaluate(self, x, v, force, want_jac):
        return {}

    def stiffness_product(self, w, out):
        pass

    def add_to_system(self, data, alpha, beta):
        pass

    def energy(self, x):
        return 0.0

    def max_strain(self, x):
        return 0.0


class _SpringSet(ForceTerm):
    """Springs on local vertices: the stencils and Jacobian buffers they share."""

    def __init__(self, name, springs, rest):
        self.name = name
        self.springs = np.ascontiguousarray(springs, dtype=np.int64)
        self.rest = np.ascontiguousarray(rest, dtype=np.float64)
        ns = self.springs.shape[0]
        self.hess = np.zeros((ns, 3, 3))
        self.unit = np.zeros((ns, 3))
        self._zero = np.zeros(ns)
        self.slots = None

    def stencils(self):
        return [self.springs]

    def bind(self, pattern):
        self.slots = pattern.slots_for(self.springs)


class SpringTerm(_SpringSet):
    """Elastic springs of some kinds (membrane: structural + shear; bending: flexion)."""

    def __init__(self, name, springs, rest, stiffness, weight, strain_mask, clamp=True):
        super().__init__(name, springs, rest)
        self.k = np.ascontiguousarray(stiffness, dtype=np.float64)
        self.weight = np.ascontiguousarray(weight, dtype=np.float64)
        self.strain_mask = np.ascontiguousarray(strain_mask, dtype=np.bool_)
        self.clamp = clamp

    def evaluate(self, x, v, force, want_jac):
        energy, strain = sk.spring_forces(x, v, self.springs, self.rest, self.k, self._zero,
                                          self.weight, self.clamp, want_jac, force,
                                          self.hess, self.unit, self.strain_mask)
        return {"elastic_energy": energy, "max_strain": strain}

    def stiffness_product(self, w, out):
        sk.spring_stiffness_product(self.springs, self.hess, w, out)

    def add_to_system(self, data, alpha, beta):
        sk.add_spring_blocks(self.hess, self.unit, self._zero, alpha, 0.0, self.slots, data)

    def energy(self, x):
        return sk.spring_energy_only(x, self.springs, self.rest, self.k, self.weight)

    def max_strain(self, x):
        """Largest engineering strain of the structural springs (strain_mask)."""
        if not self.strain_mask.any():
            return 0.0
        sp, rest = self.springs[self.strain_mask], self.rest[self.strain_mask]
        d = x[sp[:, 0]] - x[sp[:, 1]]
        return float(np.max((np.sqrt(np.einsum("ij,ij->i", d, d)) - rest) / rest, initial=0.0))


class SpringDampingTerm(_SpringSet):
    """Damping along every spring on the relative velocity of its ends."""

    def __init__(self, springs, rest, damping):
        super().__init__("force:damping", springs, rest)
        self.c = np.ascontiguousarray(damping, dtype=np.float64)
        self._mask = np.zeros(self.springs.shape[0], dtype=np.bool_)

    def evaluate(self, x, v, force, want_jac):
        # zero stiffness: only the damping part of the spring force remains
        sk.spring_forces(x, v, self.springs, self.rest, self._zero, self.c, self._zero,
                         True, want_jac, force, self.hess, self.unit, self._mask)
        return {}

    def add_to_system(self, data, alpha, beta):
        sk.add_spring_blocks(self.hess, self.unit, self.c, 0.0, beta, self.slots, data)


class GravityTerm(ForceTerm):
    name = "force:gravity"
    has_jacobian = False

    def __init__(self, mass, gravity, weight):
        self.mg = mass[:, None] * np.asarray(gravity, dtype=np.float64)[None, :]
        self.weight = weight          # 1 for owned vertices, 0 for ghosts

    def evaluate(self, x, v, force, want_jac):
        force += self.mg
        return {}

    def energy(self, x):
        return -float(np.sum(self.weight * np.einsum("ij,ij->i", self.mg, x)))


class DragTerm(ForceTerm):
    """Linear air drag f = -drag * area * v on each vertex."""
    name = "force:drag"

    def __init__(self, area, drag, n_owned):
        self.coef = drag * np.asarray(area, dtype=np.float64)
        self.n_owned = n_owned
        self.diag_slots = None

    def bind(self, pattern):
        self.diag_slots = pattern.diag_slots

    def evaluate(self, x, v, force, want_jac):
        force -= self.coef[:, None] * v
        return {}

    def add_to_system(self, data, alpha, beta):
        d = beta * self.coef[: self.n_owned]
        data[self.diag_slots, 0, 0] += d
        data[self.diag_slots, 1, 1] += d
        data[self.diag_slots, 2, 2] += d


def build_terms(cfg, model, layout):
    """The force terms a scene asks for, on this rank's local arrays, in stage order."""
    local = layout.local_input
    own = np.zeros(layout.n_local)
    own[: layout.n_owned] = 1.0
    ids = layout.local_spring_ids
    lsp = layout.local_springs
    # a spring counts once globally: each owned end carries half of it
    spring_weight = 0.5 * ((lsp[:, 0] < layout.n_owned).astype(float)
                           + (lsp[:, 1] < layout.n_owned).astype(float))
    kind = model.spring_kind[ids]
    terms = []
    if cfg.has("gravity"):
        terms.append(GravityTerm(model.vertex_mass[local], cfg.gravity, own))

    def spring_term(name, kinds):
        sel = np.isin(kind, kinds)
        return SpringTerm(name, lsp[sel], model.spring_rest_length[ids][sel],
                          model.spring_stiffness[ids][sel], spring_weight[sel],
                          kind[sel] == STRUCTURAL)

    material = cfg.cloth[0].material        # one law per scene (scene.build checks it)
    if cfg.has("membrane"):
        if material.model == "fem":
            terms.append(_fem_membrane(cfg, model, layout, material))
        else:
            terms.append(spring_term("force:membrane", [STRUCTURAL, SHEAR]))
    if cfg.has("bending"):
        if material.bending_kind == "flexion":
            terms.append(spring_term("force:bending", [FLEXION]))
        else:
            terms.append(_hinge_bending(cfg, model, layout, material.bending_kind))
    if cfg.has("damping"):
        sel = model.spring_damping[ids] > 0.0
        terms.append(SpringDampingTerm(lsp[sel], model.spring_rest_length[ids][sel],
                                       model.spring_damping[ids][sel]))
    if cfg.has("drag") and cfg.drag > 0.0:
        terms.append(DragTerm(model.vertex_area[local], cfg.drag, layout.n_owned))
    return terms


# friction last: its coefficients are set from every other force at the start state
FORCE_STAGES = ("force:gravity", "force:membrane", "force:bending", "force:damping", "force:drag",
                "force:friction")


def local_elements(elements: np.ndarray, layout):
    """Elements with at least one owned vertex, in local numbering, and the
    fraction of their vertices this rank owns (their energy weight)."""
    to_local = np.full(layout.part.shape[0], -1, dtype=np.int64)
    to_local[layout.local_input] = np.arange(layout.n_local)
    el = to_local[elements]
    owned = (el >= 0) & (el < layout.n_owned)
    keep = owned.any(axis=1)
    if np.any(el[keep] < 0):      # the ghost layer covers every matrix-graph neighbour
        raise RuntimeError("an element with an owned vertex reaches beyond the ghost layer")
    return el[keep], owned[keep].sum(axis=1) / elements.shape[1], np.nonzero(keep)[0]


def _fem_membrane(cfg, model, layout, material):
    from .membrane_fem import MembraneFEMTerm, orthotropic_plane_stress
    tris, weight, _ = local_elements(model.triangles, layout)
    C = orthotropic_plane_stress(*material.orthotropic())
    weft = np.broadcast_to(np.asarray(material.weft, float), (tris.shape[0], 3))
    rest = model.rest_positions[layout.local_input]
    tables = None
    if any(t is not None for t in (material.tension_weft, material.tension_warp, material.shear_curve)):
        # a missing curve keeps the linear law of Eq. 22 (its C11 / C22 / C33 slope)
        lin = lambda c: ((0.0, 0.0), (1.0, c))   # noqa: E731
        tables = (material.tension_weft or lin(C[0, 0]), material.tension_warp or lin(C[1, 1]),
                  material.shear_curve or lin(C[2, 2]))
    return MembraneFEMTerm(tris, rest, weft, C, material.strain, weight, tables=tables)


def _hinge_bending(cfg, model, layout, kind):
    """Per-hinge sums of bending.py for ``dihedral``/``isometric``; the
    per-triangle curvature of bending_shell.py for ``*_shell``."""
    from .bending import DihedralBendingTerm, IsometricBendingTerm
    from .bending_shell import JUMP_GAMMA, ShellDihedralBendingTerm, ShellIsometricBendingTerm
    shell = kind in ("dihedral_shell", "isometric_shell")
    elements = model.shell_stencil if shell else model.hinge_vertices
    local, weight, ids = local_elements(elements, layout)
    # each element takes the bending stiffness of the piece its first vertex belongs to
    piece_of_vertex = np.zeros(model.num_vertices, dtype=np.int64)
    for p, info in enumerate(model.pieces):
        piece_of_vertex[info.vertex_start:info.vertex_stop] = p
    piece_B = np.array([spec.material.bending for spec in cfg.cloth])
    B = piece_B[piece_of_vertex[elements[ids, 0]]]
    rest = model.rest_positions[layout.local_input]
    if shell:
        jump_local, jump_weight, jump_ids = local_elements(model.shell_jump_stencil, layout)
        jump_B = piece_B[piece_of_vertex[model.shell_jump_stencil[jump_ids, 0]]]
        term = ShellDihedralBendingTerm if kind == "dihedral_shell" else ShellIsometricBendingTerm
        return term(local, model.shell_present[ids], rest, B, weight,
                    jump=(jump_local, jump_B, jump_weight, JUMP_GAMMA))
    term = DihedralBendingTerm if kind == "dihedral" else IsometricBendingTerm
    return term(local, rest, B, weight)
