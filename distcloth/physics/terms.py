"""The force terms of the step, one per effect, and how each is built for a
rank's local arrays.  The contract a term keeps is in ``physics/base.py``;
the order of the terms and which effect turns each on is declared in
``distcloth/stages.py``.
"""
from __future__ import annotations

import numpy as np

from ..model import FLEXION, SHEAR, STRUCTURAL
from . import springs as sk
from .base import ForceTerm, TermSum, local_elements
from .bending import DihedralBendingTerm, FlexionLineTerm, IsometricBendingTerm, TwistCellTerm
from .bending_shell import JUMP_GAMMA, ShellDihedralBendingTerm, ShellIsometricBendingTerm
from .membrane_fem import MembraneFEMTerm, orthotropic_plane_stress, with_compression


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
        sk.spring_forces(x, v, self.springs, self.rest, self.k, self._zero, self.weight,
                         self.clamp, want_jac, force, self.hess, self.unit, self.strain_mask)

    def evaluate_between(self, x0, x1, v, force, want_jac):
        if want_jac:     # the Newton matrix: the Hessian at the midpoint
            self.evaluate(0.5 * (x0 + x1), v, np.zeros_like(force), True)
        sk.spring_discrete_gradient(np.ascontiguousarray(x0), np.ascontiguousarray(x1),
                                    self.springs, self.rest, self.k, force)

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
    dissipative = True

    def __init__(self, springs, rest, damping, weight=None):
        super().__init__("force:damping", springs, rest)
        self.c = np.ascontiguousarray(damping, dtype=np.float64)
        self.weight = np.ones_like(self.c) if weight is None else np.asarray(weight, float)
        self._mask = np.zeros(self.springs.shape[0], dtype=np.bool_)

    def evaluate(self, x, v, force, want_jac):
        # zero stiffness: only the damping part of the spring force remains
        sk.spring_forces(x, v, self.springs, self.rest, self._zero, self.c, self._zero,
                         True, want_jac, force, self.hess, self.unit, self._mask)

    def add_to_system(self, data, alpha, beta):
        sk.add_spring_blocks(self.hess, self.unit, self.c, 0.0, beta, self.slots, data)

    def dissipation(self, x, v):
        """Rayleigh's R = c (u . (v_i - v_j))^2 / 2 per spring, u its unit vector."""
        i, j = self.springs[:, 0], self.springs[:, 1]
        d = x[i] - x[j]
        vr = np.einsum("ij,ij->i", d, v[i] - v[j]) / np.linalg.norm(d, axis=1)
        return float(0.5 * np.sum(self.weight * self.c * vr * vr))


class GravityTerm(ForceTerm):
    name = "force:gravity"
    has_jacobian = False

    def __init__(self, mass, gravity, weight):
        self.mg = mass[:, None] * np.asarray(gravity, dtype=np.float64)[None, :]
        self.weight = weight          # 1 for owned vertices, 0 for ghosts

    def evaluate(self, x, v, force, want_jac):
        force += self.mg

    def energy(self, x):
        return -float(np.sum(self.weight * np.einsum("ij,ij->i", self.mg, x)))


class DragTerm(ForceTerm):
    """Linear air drag f = -drag * area * v on each vertex."""
    name = "force:drag"
    dissipative = True

    def __init__(self, area, drag, n_owned):
        self.coef = drag * np.asarray(area, dtype=np.float64)
        self.n_owned = n_owned
        self.diag_slots = None

    def bind(self, pattern):
        self.diag_slots = pattern.diag_slots

    def evaluate(self, x, v, force, want_jac):
        force -= self.coef[:, None] * v

    def dissipation(self, x, v):
        n = self.n_owned
        return float(0.5 * np.sum(self.coef[:n] * np.einsum("ij,ij->i", v[:n], v[:n])))

    def add_to_system(self, data, alpha, beta):
        d = beta * self.coef[: self.n_owned]
        data[self.diag_slots, 0, 0] += d
        data[self.diag_slots, 1, 1] += d
        data[self.diag_slots, 2, 2] += d


class LocalSprings:
    """The model's springs with at least one owned end, on local numbering,
    and the energy weight of each (a spring counts once globally: each owned
    end carries half of it)."""

    def __init__(self, model, layout):
        self.ids = layout.local_spring_ids
        self.ends = layout.local_springs
        self.weight = 0.5 * ((self.ends[:, 0] < layout.n_owned).astype(float)
                             + (self.ends[:, 1] < layout.n_owned).astype(float))
        self.kind = model.spring_kind[self.ids]
        self.rest = model.spring_rest_length[self.ids]
        self.stiffness = model.spring_stiffness[self.ids]
        self.damping = model.spring_damping[self.ids]

    def term(self, name, kinds) -> SpringTerm:
        sel = np.isin(self.kind, kinds)
        return SpringTerm(name, self.ends[sel], self.rest[sel], self.stiffness[sel],
                          self.weight[sel], self.kind[sel] == STRUCTURAL)


# --- one builder per force stage: (cfg, model, layout) -> the term ----------------
# (each called only when its effect is on; the material law is one per scene,
# which scene.build checks)

def build_gravity(cfg, model, layout) -> ForceTerm:
    own = np.zeros(layout.n_local)
    own[: layout.n_owned] = 1.0
    gravity = np.asarray(cfg.gravity, dtype=np.float64)
    if model.stitch_pairs is not None:     # a garment being sewn (sew.py)
        gravity = gravity * cfg.garment.sewing.gravity
    return GravityTerm(model.vertex_mass[layout.local_input], gravity, own)


def build_membrane(cfg, model, layout) -> ForceTerm:
    material = cfg.cloth[0].material
    if material.model == "fem":
        return _fem_membrane(model, layout, material)
    return LocalSprings(model, layout).term("force:membrane", [STRUCTURAL, SHEAR])


def build_bending(cfg, model, layout) -> ForceTerm:
    kind = cfg.cloth[0].material.bending_kind
    if kind == "flexion":
        return _flexion_bending(cfg, model, layout)
    if kind == "grid_lines":
        return _grid_line_bending(cfg, model, layout)
    return _hinge_bending(cfg, model, layout, kind)


def build_damping(cfg, model, layout) -> ForceTerm:
    springs = LocalSprings(model, layout)
    sel = springs.damping > 0.0
    return SpringDampingTerm(springs.ends[sel], springs.rest[sel], springs.damping[sel],
                             springs.weight[sel])


def build_drag(cfg, model, layout) -> ForceTerm | None:
    if cfg.drag <= 0.0:
        return None
    return DragTerm(model.vertex_area[layout.local_input], cfg.drag, layout.n_owned)


def _fem_membrane(model, layout, material):
    C = orthotropic_plane_stress(*material.orthotropic())
    tris, weight, ids = local_elements(model.triangles, layout)
    weft = np.broadcast_to(np.asarray(material.weft, float), (tris.shape[0], 3))
    if model.triangle_weft is not None:      # garments: each panel's grain
        weft = model.triangle_weft[ids]
    rest = model.rest_positions[layout.local_input]
    corners = None if model.rest_triangles is None else model.rest_triangles[ids]
    scale = None if model.triangle_scale is None else model.triangle_scale[ids]
    tables = None
    if (any(t is not None for t in (material.tension_weft, material.tension_warp,
                                    material.shear_curve)) or material.compression != 1.0):
        # a missing curve keeps the linear law of EG07 tutorial Eq. 22 (its C11 / C22 / C33 slope)
        def linear(c):
            return ((0.0, 0.0), (1.0, c))
        tables = [material.tension_weft or linear(C[0, 0]),
                  material.tension_warp or linear(C[1, 1]),
                  material.shear_curve or linear(C[2, 2])]
        if material.compression != 1.0:
            tables[:2] = [with_compression(t, material.compression) for t in tables[:2]]
    return MembraneFEMTerm(tris, rest, weft, C, material.strain, weight, tables=tables,
                           rest_corners=corners, scale=scale)


def _flexion_bending(cfg, model, layout):
    """Mass-spring bending: the flexion line elements of grid pieces
    (``FlexionLineTerm``), dihedral angles on the hinges of mesh files (their
    flexion springs, across the same hinges, span the same pairs), and the
    flexion springs of whatever has neither (garment panels)."""
    springs = LocalSprings(model, layout)
    piece_B = np.array([spec.material.bending for spec in cfg.cloth])
    piece_of_vertex = model.per_vertex(np.arange(len(model.pieces)))
    rest = model.rest_positions[layout.local_input]
    parts, covered = [], []
    if model.flexion_lines is not None:
        parts.append(_line_elements(model, model.flexion_lines, layout, rest,
                                    piece_B[piece_of_vertex]))
        covered.append(model.flexion_lines[:, [0, 2]])    # the grid flexion pairs: damping only
    if model.flexion_hinges is not None:
        hg = model.flexion_hinges
        local, weight, ids = local_elements(hg, layout)
        parts.append(DihedralBendingTerm(local, rest, piece_B[piece_of_vertex[hg[ids, 0]]],
                                         weight))
        covered.append(hg[:, 2:])               # the wing pairs: the mesh flexion springs
    n = np.int64(model.num_vertices)
    pairs = np.sort(model.spring_vertices[springs.ids], axis=1)
    other = springs.kind == FLEXION
    if covered:
        ends = np.sort(np.concatenate(covered), axis=1)
        other &= ~np.isin(pairs[:, 0] * n + pairs[:, 1], ends[:, 0] * n + ends[:, 1])
    if other.any() or not parts:
        parts.append(SpringTerm("force:bending", springs.ends[other], springs.rest[other],
                                springs.stiffness[other], springs.weight[other],
                                np.zeros(int(other.sum()), dtype=bool)))
    return parts[0] if len(parts) == 1 else TermSum("force:bending", parts)


def _grid_line_bending(cfg, model, layout):
    """Continuum bending of grid pieces: line elements along the rows and
    columns and a twist element per cell (``FlexionLineTerm`` +
    ``TwistCellTerm``, B/2 |K|^2 with bending Poisson ratio 0)."""
    piece_B = np.array([spec.material.bending for spec in cfg.cloth])
    piece_of_vertex = model.per_vertex(np.arange(len(model.pieces)))
    rest = model.rest_positions[layout.local_input]
    none = np.zeros((0, 4), dtype=np.int64)
    lines = none[:, :3] if model.flexion_lines is None else model.flexion_lines
    cells = none if model.twist_cells is None else model.twist_cells
    local, weight, ids = local_elements(cells, layout)
    return TermSum("force:bending", [
        _line_elements(model, lines, layout, rest, piece_B[piece_of_vertex]),
        TwistCellTerm(local, rest, piece_B[piece_of_vertex[cells[ids, 0]]], weight)])


def _line_elements(model, lines, layout, rest, vertex_B):
    """``FlexionLineTerm`` on the grid lines (first, middle, last), each with
    the bending stiffness and lumped area of its middle vertex."""
    local, weight, ids = local_elements(lines[:, [0, 2, 1, 1]], layout)
    mid = lines[ids, 1]
    return FlexionLineTerm(local[:, [0, 2, 1]], rest, vertex_B[mid], model.vertex_area[mid],
                           weight)


def _hinge_bending(cfg, model, layout, kind):
    """Per-hinge sums of bending.py for ``dihedral``/``isometric``; the
    per-triangle curvature of bending_shell.py for ``*_shell``."""
    shell = kind in ("dihedral_shell", "isometric_shell")
    elements = model.shell_stencil if shell else model.hinge_vertices
    local, weight, ids = local_elements(elements, layout)
    # each element takes the bending stiffness of the piece its first vertex belongs to
    piece_of_vertex = model.per_vertex(np.arange(len(model.pieces)))
    piece_B = np.array([spec.material.bending for spec in cfg.cloth])
    B = piece_B[piece_of_vertex[elements[ids, 0]]]
    rest = model.rest_positions[layout.local_input]
    if shell:
        jump_local, jump_weight, jump_ids = local_elements(model.shell_jump_stencil, layout)
        jump_B = piece_B[piece_of_vertex[model.shell_jump_stencil[jump_ids, 0]]]
        term = ShellDihedralBendingTerm if kind == "dihedral_shell" else ShellIsometricBendingTerm
        return term(local, model.shell_present[ids], rest, B, weight,
                    jump=(jump_local, jump_B, jump_weight, JUMP_GAMMA))
    if model.hinge_scale is not None:        # seams and fused regions
        B = B * model.hinge_scale[ids]
    term = DihedralBendingTerm if kind == "dihedral" else IsometricBendingTerm
    points = None if model.hinge_rest is None else model.hinge_rest[ids]
    return term(local, rest, B, weight, rest_points=points)
