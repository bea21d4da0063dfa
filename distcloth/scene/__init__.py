"""Scene building: grids and triangle-mesh files -> the Model."""
from .build import build_model

__all__ = ["build_model"]
