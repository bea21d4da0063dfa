"""The project's own sewing patterns (configs/garments/*.yaml), at the edge
length their scenes use: every panel meets the meshing guarantees, every seam
pairs its two sides one to one, and every garment starts where its panels
are placed without touching the body it is sized for or crossing itself, so
the scenes need no pre-positioning to start.

Every rank meshes and checks the same patterns (no MPI in this file).
"""
from __future__ import annotations

import pathlib

import numpy as np
import pytest

from distcloth.garment import load_pattern, mesh_pattern
from distcloth.garment.mesh import triangle_angles
from distcloth.garment.report import edge_lengths
from distcloth.garment.start_check import check_start, describe
from distcloth.scene.meshio import read_mesh

ROOT = pathlib.Path(__file__).resolve().parents[1]
PATTERNS = sorted((ROOT / "configs" / "garments").glob("*.yaml"))
BODY = ROOT / "configs" / "meshes" / "mean_all.obj"
H = 0.03            # the bundled scenes' edge length (the sleeved dress: 2.5 cm)
# Gmsh's frontal mesher leaves edges up to about 1.4 h (tests/test_garment_mesh.py);
# nothing is inserted much closer than the outline's segments
LONGEST, SHORTEST = 1.5, 0.4


@pytest.fixture(scope="module")
def body():
    return read_mesh(str(BODY))


@pytest.mark.parametrize("path", PATTERNS, ids=[p.stem for p in PATTERNS])
def test_bundled_pattern_meshes_and_starts_clear_of_the_body(path, body):
    mesh = mesh_pattern(load_pattern(str(path)), H)
    for p in mesh.panels:
        assert triangle_angles(p.vertices, p.triangles).min() >= 25.0 - 1e-9, p.panel.name
        length = edge_lengths(p.vertices, p.triangles) / H
        assert SHORTEST <= length.min() and length.max() <= LONGEST, p.panel.name
    assert mesh.seams, path.name
    for s in mesh.seams:
        a, b = s.pairs[:, 0], s.pairs[:, 1]
        # one to one: no vertex of either side is paired twice
        assert len(np.unique(a)) == len(a) and len(np.unique(b)) == len(b), s.stitch.label
        assert not np.intersect1d(a, b).size, s.stitch.label
    # the placement is in the body file's frame (y up, metres); the start check
    # is the one the driver runs before any step (generalized winding number,
    # exact triangle-triangle crossings)
    report = check_start(mesh.positions, mesh.triangles, *body)
    assert report.ok, f"{path.name}: {describe(report)}"
