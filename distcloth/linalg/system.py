"""The implicit system in PETSc: fixed-pattern blocked matrix, KSP, checks.

The matrix is BAIJ with 3x3 blocks by default (EG07 tutorial, Part 1 §5.7), or AIJ
with block size 3 (needed by GAMG); both are first filled through the same
blocked CSR call from the pattern's value array, and AIJ afterwards straight
into its storage (linalg/aij_values.py: PETSc's blocked call on AIJ inserts a
scalar at a time).  Its sparsity is preallocated exactly and frozen
(NEW_NONZERO_ALLOCATION_ERR): every step only overwrites values.  Rows are
set only by their owner (NO_OFF_PROC_ENTRIES), so assembly sends nothing.

Default solver: CG preconditioned by block Jacobi over the ranks with SOR on
each rank's diagonal block (EG07 tutorial, Part 1 §5.6).  PETSc's BAIJ SOR allows only
omega = 1, so the sub-preconditioner is symmetric Gauss-Seidel.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import ctypes

import numpy as np

from .aij_values import AIJBlockWriter
from .log_events import logged
from .petsc import PREFIX, check_call, libpetsc, petsc
from .sgs32 import ATTR

# an aimed solve's relative tolerance stays within these: below, round-off and
# a cloth at rest (whose step error and |b| both vanish) would ask CG for
# digits it cannot give; above, the loosest a Newton correction takes
# (integrate/implicit.py, MAX_FORCING)
AIMED_RTOL = 1.0e-6
MAX_AIMED_RTOL = 1.0e-2


class SolverFailure(Exception):
    pass


@dataclass
class SolveInfo:
    iterations: int
    reason: int
    residual: float      # true relative residual |b - A y| / |b|
    # (n_owned, 3) A dv - b of the unconstrained system at the solution: at a
    # constrained vertex, the impulse its constraint applied (filled by the caller)
    reaction: np.ndarray | None = None


class LinearSystem:
    def __init__(self, layout, pattern, comm, mat_type: str = "baij", warm_start: bool = False,
                 pc_rebuild_every: int = 1):
        PETSc = petsc()
        self.comm = comm.mpi_comm
        self._dcomm = comm
        self.pattern = pattern
        n, N = layout.n_owned, int(layout.ownership[-1])
        self.n_owned = n
        is_owned_col = np.zeros(layout.n_local, dtype=bool)
        is_owned_col[:n] = True
        d_nnz, o_nnz = pattern.counts(is_owned_col)
        l2g = layout.local_to_global
        self.indptr = pattern.indptr.astype(PETSc.IntType)
        self.gcols = l2g[pattern.block_cols].astype(PETSc.IntType)

        A = PETSc.Mat().create(self.comm)
        A.setSizes(((3 * n, 3 * N), (3 * n, 3 * N)), bsize=3)
        A.setType(PETSc.Mat.Type.BAIJ if mat_type == "baij" else PETSc.Mat.Type.AIJ)
        A.setBlockSize(3)
        if mat_type == "baij":
            A.setPreallocationNNZ((d_nnz, o_nnz))
        else:
            A.setPreallocationNNZ((np.repeat(3 * d_nnz, 3), np.repeat(3 * o_nnz, 3)))
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        A.setOption(PETSc.Mat.Option.NO_OFF_PROC_ENTRIES, True)
        # blocks are passed contiguous per block; column orientation + transposed
        # blocks makes PETSc read each 3x3 block the right way round
        A.setOption(PETSc.Mat.Option.ROW_ORIENTED, False)
        self.A = A
        self.mat_type = mat_type
        # AIJ: after the first fill, values go straight into its storage
        self._aij_writer = None
        self._aij_slots = l2g if mat_type != "baij" else None
        self.warm_start = warm_start
        # rebuild the preconditioner every k-th solve and reuse it between: an
        # SPD preconditioner of a slightly older matrix keeps CG correct (only
        # the iteration count can grow) and saves AMG set-up, the larger cost
        self.pc_rebuild_every = max(1, int(pc_rebuild_every))
        self.solves = 0
        self._reuse_next = False
        self._reuses = 0        # solves that kept the last preconditioner (tests read it)
        self._correcting = False
        self.b = A.createVecLeft()
        self.y = A.createVecRight()
        self._held = None          # the warm start, kept aside while a correction is solved
        self._target = None        # an absolute residual the next solves aim at (aimed)
        self.r = A.createVecLeft()
        self.ksp = PETSc.KSP().create(self.comm)
        self.ksp.setOptionsPrefix(PREFIX)

    def set_values(self, data: np.ndarray) -> None:
        """Put the owned rows' blocks ``data`` (nnzb, 3, 3) into the matrix;
        through the blocked CSR call ``data`` is transposed in place for the
        call and back after, not copied: at 1M vertices a copy is 0.7 GB per
        rank."""
        if not data.flags.c_contiguous:
            data = np.ascontiguousarray(data)
        if self._aij_writer is not None:
            self._aij_writer.write(data)
        else:
            _transpose_blocks(data)
            try:
                self.A.setValuesBlockedCSR(self.indptr, self.gcols, data)
            finally:
                _transpose_blocks(data)
            self.A.assemble()
            if self._aij_slots is not None:
                self._aij_writer = self._aij_block_writer()
                self._aij_slots = None
        # the same blocks for preconditioners written in Python (sgs32) only:
        # held here, they would outlive the step (two filtered copies at peak)
        if petsc().Options().getString(PREFIX + "pc_type", "") == "python":
            self.A.setAttr(ATTR, (self.pattern.indptr, self.pattern.block_cols, data,
                                  self.n_owned))

    def _aij_block_writer(self):
        """The writer for later fills, if every rank's storage is laid out as
        its pattern says (else all keep the blocked call)."""
        lib = libpetsc()
        if lib is None:
            return None
        writer = AIJBlockWriter(lib, self.A, self.pattern.block_rows, self.pattern.block_cols,
                                self.n_owned, self._aij_slots)
        if self._dcomm.max(np.array([0.0 if writer.matches else 1.0]))[0] > 0:
            return None
        return writer

    def configure(self) -> None:
        """Apply the options database to the KSP and set it up (first matrix must be set)."""
        ksp = self.ksp
        ksp.setOperators(self.A)
        ksp.setType("cg")
        ksp.getPC().setType("bjacobi")
        ksp.setFromOptions()
        ksp.setUp()
        if ksp.getPC().getType() == "bjacobi":
            ksp.setUpOnBlocks()

    def keep_preconditioner(self) -> None:
        """The next solve reuses the last one's multigrid preconditioner: a
        contact pass's re-solve, whose matrix differs from the last only in
        the rows of contacts that changed. Still SPD, so CG stays correct
        (only the iteration count can grow); an AMG set-up costs several
        solves' worth of iterations at 100k vertices, block Jacobi's almost
        nothing, so only AMG preconditioners are kept."""
        self._reuse_next = self.ksp.getPC().getType() in ("gamg", "hypre", "ml")

    @contextmanager
    def correcting(self):
        """Solves inside are Newton corrections: they start from zero and
        leave the warm start (the last solution of a step's own solve) as it
        was.  A correction is a poor start for the next step's velocity
        change, and the step's solution a poor one for a correction: on the
        hanging square with two Newton iterations a step, letting the
        correction be the next warm start cost the step's first solve a
        fifth more CG iterations."""
        if self._held is None:
            self._held = self.y.duplicate()
        self.y.copy(self._held)
        self._correcting = True
        try:
            yield
        finally:
            self._correcting = False
            self._held.copy(self.y)

    @property
    def rtol(self) -> float:
        return self.ksp.getTolerances()[0]

    @contextmanager
    def loosened(self, rtol: float | None):
        """Solves inside use the relative tolerance ``rtol`` where it is looser
        than the configured one (None: unchanged); restored on exit."""
        old = self.rtol
        if rtol is None or rtol <= old:
            yield
            return
        self.ksp.setTolerances(rtol=rtol)
        try:
            yield
        finally:
            self.ksp.setTolerances(rtol=old)

    @contextmanager
    def aimed(self, target: float | None):
        """Solves inside stop where |b - A y| <= ``target`` (None: at the
        configured relative tolerance), as a relative tolerance between
        AIMED_RTOL and MAX_AIMED_RTOL of their own |b|; restored on exit."""
        self._target = target
        try:
            yield
        finally:
            self._target = None

    def block_jacobi_blocks(self) -> int:
        """Local number of block-Jacobi blocks (0 if another preconditioner is in use)."""
        pc = self.ksp.getPC()
        if pc.getType() != "bjacobi":
            return 0
        return bjacobi_local_blocks(pc)

    def describe(self) -> str:
        pc = self.ksp.getPC()
        sub = ""
        if pc.getType() == "bjacobi":
            opts = petsc().Options()
            sub = "/" + opts.getString(PREFIX + "sub_pc_type", "ilu")
        return (f"{self.ksp.getType()} + {pc.getType()}{sub}, {self.mat_type} matrix, "
                f"rtol {self.ksp.getTolerances()[0]:g}, norm {_norm_name(self.ksp.getNormType())}"
                + (", warm start" if self.warm_start else "")
                + (f", preconditioner rebuilt every {self.pc_rebuild_every} solves"
                   if self.pc_rebuild_every > 1 else ""))

    def solve(self, rhs: np.ndarray, guess: np.ndarray | None = None) -> tuple[np.ndarray, SolveInfo]:
        """Solve A y = rhs for this rank's rows; raises SolverFailure on divergence
        (the reason is the same on every rank, so all ranks raise together).
        The initial guess is ``guess`` (n_owned, 3) if given, else with
        ``warm_start`` the previous solution, else zero."""
        self.b.array[:] = rhs.ravel()
        reuse = self._reuse_next or self.solves % self.pc_rebuild_every != 0
        self.ksp.getPC().setReusePreconditioner(reuse)
        self._reuses += reuse
        self._reuse_next = False
        self.solves += 1
        if guess is not None:
            with logged("solve:guess"):
                self.ksp.setInitialGuessNonzero(self._better_than_zero(guess))
        elif self.warm_start and not self._correcting:
            # the last solution: a good start for the next step's velocity
            # change, a poor one for a Newton correction (whose right-hand side
            # is the small residual): checked like any guess
            with logged("solve:guess"):
                self.ksp.setInitialGuessNonzero(self._better_than_zero(self.y.array.copy()))
        else:
            self.y.set(0.0)
            self.ksp.setInitialGuessNonzero(False)
        if self._target is None:
            self.ksp.solve(self.b, self.y)
        else:
            self._solve_aimed()
        reason = self.ksp.getConvergedReason()
        its = self.ksp.getIterationNumber()
        with logged("solve:check"):        # the true residual, whatever norm CG used
            self.A.mult(self.y, self.r)
            self.r.aypx(-1.0, self.b)
            rnorm, bnorm = _norms(self.r, self.b)
        res = rnorm / bnorm if bnorm > 0 else rnorm
        if reason < 0:
            raise SolverFailure(f"linear solve did not converge: {_reason_name(reason)} "
                                f"after {its} iterations, true relative residual {res:.3g}")
        return self.y.array.reshape(-1, 3).copy(), SolveInfo(its, reason, res)

    def _solve_aimed(self) -> None:
        """The solve at the relative tolerance that stops it at the aimed
        absolute residual (within AIMED_RTOL and MAX_AIMED_RTOL of |b|)."""
        configured = self.rtol
        bnorm = self.b.norm()
        if bnorm > 0:
            self.ksp.setTolerances(rtol=float(np.clip(self._target / bnorm, AIMED_RTOL,
                                                      MAX_AIMED_RTOL)))
        try:
            self.ksp.solve(self.b, self.y)
        finally:
            self.ksp.setTolerances(rtol=configured)

    def _better_than_zero(self, guess: np.ndarray) -> bool:
        """Put ``guess`` into y if its residual is below |b| (the solver's
        tolerance is relative to |b|: a guess worse than zero, as where nearly
        every row is constrained and b vanishes, would only trip its
        divergence test); else zero y."""
        self.y.array[:] = guess.ravel()
        self.A.mult(self.y, self.r)
        self.r.aypx(-1.0, self.b)
        rnorm, bnorm = _norms(self.r, self.b)
        if rnorm < bnorm:
            return True
        self.y.set(0.0)
        return False

    def destroy(self):
        for obj in (self.ksp, self.A, self.b, self.y, self.r, self._held):
            if obj is not None:
                obj.destroy()


def _norms(*vecs) -> list[float]:
    """The 2-norms of the vectors in one global reduction (PETSc merges
    split-phase VecNormBegin/End on one communicator): on 2 ranks each
    reduction is a synchronisation, the per-solve cost that is not CG's."""
    for v in vecs:
        v.normBegin()
    return [v.normEnd() for v in vecs]


def _transpose_blocks(data: np.ndarray) -> None:
    """Transpose every 3x3 block of ``data`` in place (one off-diagonal pair at
    a time: temporaries of a ninth of its size)."""
    for a, b in ((0, 1), (0, 2), (1, 2)):
        upper = data[:, a, b].copy()
        data[:, a, b] = data[:, b, a]
        data[:, b, a] = upper


def bjacobi_local_blocks(pc) -> int:
    """PCBJacobiGetSubKSP's local block count (petsc4py 3.18 does not wrap it)."""
    PETSc = petsc()
    lib = libpetsc()
    itype = ctypes.c_int64 if np.dtype(PETSc.IntType).itemsize == 8 else ctypes.c_int32
    n, first, ksps = itype(0), itype(0), ctypes.c_void_p(0)
    err = lib.PCBJacobiGetSubKSP(ctypes.c_void_p(pc.handle), ctypes.byref(n), ctypes.byref(first),
                                 ctypes.byref(ksps))
    check_call(err, "PCBJacobiGetSubKSP")
    return int(n.value)


def _norm_name(norm: int) -> str:
    PETSc = petsc()
    for name in ("NONE", "PRECONDITIONED", "UNPRECONDITIONED", "NATURAL"):
        if getattr(PETSc.KSP.NormType, name) == norm:
            return name.lower()
    return str(norm)


def _reason_name(reason: int) -> str:
    PETSc = petsc()
    for name in dir(PETSc.KSP.ConvergedReason):
        if not name.startswith("_") and getattr(PETSc.KSP.ConvergedReason, name) == reason:
            return name
    return str(reason)
