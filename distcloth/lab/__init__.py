"""A virtual textile lab: ``distcloth lab SCENE-OR-PRESET`` runs the standard
fabric tests on a material and reports what a textile lab would.

Each test is a module with ``run(material, base_dir, comm, resolution=...)``
returning a result, and a row of the report (report.py); every run is
collective (the specimens are simulated in process on the job's ranks).
"""
from __future__ import annotations

from . import cusick, kes_bending, kes_shear, kes_tensile, peirce

TESTS = {
    "tensile": ("KES-FB1 tensile: load-elongation to 500 gf/cm, EMT, LT, WT", kes_tensile),
    "shear": ("KES-FB1 shear: shear force against angle, G", kes_shear),
    "bending": ("KES-FB2 pure bending: moment against curvature, B", kes_bending),
    "peirce": ("Peirce cantilever (ASTM D1388): bending length and flexural rigidity", peirce),
    "cusick": ("Cusick drape (ISO 9073-9 geometry): drape coefficient and folds", cusick),
}
RESOLUTIONS = ("coarse", "standard")
