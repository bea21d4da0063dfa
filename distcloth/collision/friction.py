"""The Coulomb friction rule every after-the-solve response shares.

A contact whose normal velocity changed by dv_n may change its tangential
velocity (relative to the body, or between the primitives of a cloth pair)
by at most mu dv_n, and never past zero (Bridson et al. 2002 §7.3): the
fraction of the tangential speed it removes is min(mu dv_n, |v_t|) / |v_t|,
1 when it sticks.  Used per vertex for body contacts of explicit schemes
(``collision/response.py``) and per impulse in the triangle-contact pipeline
(``collision/impulses.py``).  Implicit schemes take body friction into the
solve instead (``physics/contact_friction.py``); image-space colliders use
Vassilev et al. 2001 Eq. 15 (``collision/imagespace.py``); which law a
contact gets is decided once, in ``collision/contact.py``.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def coulomb_fraction(speed: float, drop: float) -> float:
    """Fraction of the tangential speed removed by a Coulomb impulse allowed
    to remove ``drop`` = mu dv_n (0 for a contact at rest)."""
    return min(drop, speed) / speed if speed > 0.0 else 0.0


@njit(cache=True)
def coulomb_fractions(speed: np.ndarray, drop: np.ndarray) -> np.ndarray:
    out = np.empty(speed.shape[0])
    for i in range(speed.shape[0]):
        out[i] = coulomb_fraction(speed[i], drop[i])
    return out
