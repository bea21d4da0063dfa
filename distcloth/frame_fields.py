"""The per-frame fields a run writes beside the positions (result file
format 3): each vertex's velocity and contact flag, each triangle's strain.

* ``velocity`` (n, 3) m/s: the committed state's velocity.
* ``contact`` (n,) int8: 1 where the step's contacts held the vertex, or the
  fail-safe put it back, and it ended within the contact band of a collider
  (the state's ``touching``, which the next step keeps as contacts); 0 before
  the first step and in a scene without colliders.
* ``strain`` (nt,) per triangle (Cell data in ParaView): the largest
  principal engineering strain, stretch - 1, from the triangle's rest shape
  (physics/strain_field.py).  Per triangle because that is what the FE
  membrane computes (a linear triangle has constant strain).

Vertex rows come in the rank's owned order, triangle rows for the triangles
``h5writer.triangle_rows`` gives the rank (those whose first vertex it owns),
whose corners are all local: every triangle couples its vertices in the
matrix graph, so the ghost layer holds the other corners.
"""
from __future__ import annotations

import numpy as np

from .io.h5writer import FrameField, triangle_rows
from .physics.strain_field import principal_strain, rest_metric

FRAME_FIELDS = (FrameField("velocity", "vertex", 3), FrameField("contact", "vertex", 1, "i1"),
                FrameField("strain", "triangle", 1))


class FrameFields:
    """Computes one rank's rows of the fields from the State."""

    def __init__(self, model, layout, rank: int, ghosts):
        ids = triangle_rows(model.triangles, layout.part, rank)
        self.corners = layout.input_to_local()[model.triangles[ids]]
        if np.any(self.corners < 0):
            raise RuntimeError("a triangle of this rank reaches beyond the ghost layer")
        rest = (model.rest_positions[model.triangles[ids]] if model.rest_triangles is None
                else model.rest_triangles[ids])
        self.metric = rest_metric(rest)
        self.n_owned = layout.n_owned
        self.ghosts = ghosts

    def values(self, state) -> dict[str, np.ndarray]:
        """Collective (a ghost refresh): {name: this rank's rows}."""
        n = self.n_owned
        # a copy with fresh ghost rows: the strain of a triangle with a ghost
        # corner must not depend on when the ghosts were last exchanged
        x = state.x.copy()
        self.ghosts.update(x)
        touching = state.touching
        contact = (np.zeros(n, dtype=np.int8) if touching is None
                   else np.asarray(touching)[:, :n].any(axis=0).astype(np.int8))
        return {"velocity": state.v[:n], "contact": contact,
                "strain": principal_strain(x[self.corners], self.metric)}
