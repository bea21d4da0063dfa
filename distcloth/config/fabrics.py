"""Named fabrics a scene can start from: ``material: {preset: denim, bending: 2e-4}``.

Every value here is ILLUSTRATIVE: chosen to be of the order of magnitude of
KES/FAST measurements of such fabrics as discussed in the EG07 tutorial, Part 2 §1
(which gives no numeric tables), not taken from a specific table of a
specific publication.  No value may be given a citation it does not have;
replace an entry with measured data, and its source, when one is at hand.

Units: density kg/m², moduli times thickness N/m (continuum membrane,
model: fem), bending stiffness N·m.  nu_warp follows from the symmetry of
the EG07 tutorial, Part 1 Eq. 22 (nu_warp = nu_weft E_warp / E_weft).
"""
from __future__ import annotations

FABRICS: dict[str, dict] = {
    #                 density  E_weft   E_warp   G      nu_weft  bending
    "cotton":         dict(density=0.15, E_weft=5000.0, E_warp=4000.0, G=50.0, nu_weft=0.2,
                           bending=1.0e-5, source="illustrative"),
    "wool":           dict(density=0.25, E_weft=1500.0, E_warp=1200.0, G=30.0, nu_weft=0.2,
                           bending=2.0e-5, source="illustrative"),
    "denim":          dict(density=0.40, E_weft=15000.0, E_warp=10000.0, G=200.0, nu_weft=0.2,
                           bending=1.0e-4, source="illustrative"),
    "silk":           dict(density=0.07, E_weft=2000.0, E_warp=1800.0, G=10.0, nu_weft=0.2,
                           bending=2.0e-6, source="illustrative"),
    "polyester_knit": dict(density=0.20, E_weft=200.0, E_warp=100.0, G=10.0, nu_weft=0.4,
                           bending=5.0e-6, source="illustrative"),
}
