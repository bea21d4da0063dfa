"""Scene building: grids, triangle-mesh files and sewing patterns -> the Model."""
from __future__ import annotations

__all__ = ["build_model"]


def __getattr__(name: str):
    if name == "build_model":
        # on first use: the collision package reads mesh files with scene.meshio,
        # and scene.build dresses garments on collision's bodies, so importing
        # scene.build with the package would make the two import each other
        from .build import build_model
        return build_model
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
