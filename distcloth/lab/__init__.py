"""A virtual textile lab: ``distcloth lab SCENE-OR-PRESET`` runs the standard
fabric tests on a material and reports what a textile lab would.

Each test is a module with ``run(material, base_dir, comm, resolution=...)``
returning a result, and a row of the report (report.py); every run is
collective (the specimens are simulated in process on the job's ranks).
"""
from __future__ import annotations

from . import cusick, peirce

TESTS = {
    "peirce": ("Peirce cantilever (ASTM D1388): bending length and flexural rigidity", peirce),
    "cusick": ("Cusick drape (ISO 9073-9 geometry): drape coefficient and folds", cusick),
}
RESOLUTIONS = ("coarse", "standard")
