"""The shadow of a draped specimen: the area of its vertical projection.

A drapemeter (Cusick 1968; ISO 9073-9) measures the area of the shadow a
point source above the specimen casts on a plane below, i.e. the union of
the projected triangles.  Each rank rasterises the triangles it owns on one
fixed grid centred on the specimen's axis (study/metrics.py's rasteriser: a
cell counts when its centre is under a triangle); the caller ORs the ranks'
grids.  With cell size p the area error is at most the outline's length
times p / 2, and far less on curved outlines whose half-cells cancel.
"""
from __future__ import annotations

import numpy as np

from ..study.metrics import shadow_cells


def shadow_mask(xy: np.ndarray, triangles: np.ndarray, half_width: float,
                pixel: float) -> np.ndarray:
    """(n, n) float mask, 1 where a cell of the square [-half_width, half_width]^2
    (centred on the specimen's axis) is under a triangle."""
    n = int(np.ceil(2.0 * half_width / pixel))
    return shadow_cells(xy, triangles, pixel, (-half_width, -half_width), (n, n)).astype(float)


def drape_coefficient(shadow_area: float, specimen_radius: float, clamp_radius: float) -> float:
    """Cusick's drape coefficient (A_shadow - A_disc) / (A_specimen - A_disc):
    1 for a specimen that stays flat, 0 for one hanging straight down."""
    disc = np.pi * clamp_radius ** 2
    return (shadow_area - disc) / (np.pi * specimen_radius ** 2 - disc)


def node_count(mask: np.ndarray, pixel: float, clamp_radius: float) -> int:
    """Folds (nodes) of the drape: the maxima of the shadow's outline radius over
    the angle, after a circular smoothing over 10 degrees (cell noise), whose
    prominence (the drop to the lowest point before a higher maximum, on
    either side) is at least a quarter of the outline's range: a ripple on a
    fold's crest is not a fold."""
    n = mask.shape[0]
    c = (np.arange(n) + 0.5) * pixel - 0.5 * n * pixel
    X, Y = np.meshgrid(c, c, indexing="ij")
    r = np.hypot(X, Y)
    covered = mask > 0.5
    bins = 360
    k = np.minimum((np.mod(np.arctan2(Y, X), 2 * np.pi) / (2 * np.pi) * bins).astype(int),
                   bins - 1)
    outline = np.full(bins, clamp_radius)
    np.maximum.at(outline, k[covered], r[covered])
    kernel = np.ones(10) / 10.0
    smooth = np.convolve(np.concatenate([outline[-10:], outline, outline[:10]]), kernel,
                         mode="same")[10:-10]
    span = smooth.max() - smooth.min()
    if span < 2.0 * pixel:          # a round shadow: no folds
        return 0
    # on three turns, so that prominences see around the circle; count the middle one
    # scipy.signal (with scipy.stats: 0.5 s of imports) only when a lab test counts
    # nodes, not in every distcloth command that imports the lab's parser
    from scipy.signal import find_peaks
    peaks, _ = find_peaks(np.tile(smooth, 3), prominence=0.25 * span)
    return int(np.count_nonzero((peaks >= bins) & (peaks < 2 * bins)))
