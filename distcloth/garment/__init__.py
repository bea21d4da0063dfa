"""Garments: sewing patterns read and meshed panel by panel, ready for sewing."""
from .mesh import GarmentMesh, MeshError, PanelMesh, SeamMesh, mesh_pattern
from .pattern import (Edge, Panel, Pattern, PatternError, SeamSide, Stitch, load_pattern,
                      read_compact, read_garmentcode, to_compact)

__all__ = ["Edge", "GarmentMesh", "MeshError", "Panel", "PanelMesh", "Pattern", "PatternError",
           "SeamMesh", "SeamSide", "Stitch", "load_pattern", "mesh_pattern", "read_compact",
           "read_garmentcode", "to_compact"]
