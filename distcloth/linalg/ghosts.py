"""Owned -> ghost copies through PETSc ghosted vectors (scatter built once).

One ghosted Vec per row width (3 for positions, 6 for positions and
velocities together) so a step needs one exchange for x and v.
"""
from __future__ import annotations

import numpy as np


class GhostExchange:
    def __init__(self, layout):
        from petsc4py import PETSc
        self.PETSc = PETSc
        self.n_owned, self.n_ghost = layout.n_owned, layout.n_ghost
        self.ghost_globals = layout.input_to_global[layout.ghost_input].astype(PETSc.IntType)
        self._vecs = {}

    def _vec(self, width):
        if width not in self._vecs:
            PETSc = self.PETSc
            self._vecs[width] = PETSc.Vec().createGhost(
                self.ghost_globals, size=(width * self.n_owned, PETSc.DECIDE), bsize=width,
                comm=PETSc.COMM_WORLD)
        return self._vecs[width]

    def update(self, *arrays: np.ndarray) -> None:
        """Fill the ghost rows of each (n_local, k) array from their owners, in place."""
        widths = [a.shape[1] for a in arrays]
        width = sum(widths)
        vec = self._vec(width)
        n = self.n_owned
        with vec.localForm() as lf:
            buf = lf.array.reshape(-1, width)
            col = 0
            for a, w in zip(arrays, widths):
                buf[:n, col:col + w] = a[:n]
                col += w
        vec.ghostUpdate(addv=self.PETSc.InsertMode.INSERT, mode=self.PETSc.ScatterMode.FORWARD)
        with vec.localForm() as lf:
            buf = lf.array.reshape(-1, width)
            col = 0
            for a, w in zip(arrays, widths):
                a[n:] = buf[n:, col:col + w]
                col += w

    def destroy(self):
        for v in self._vecs.values():
            v.destroy()
