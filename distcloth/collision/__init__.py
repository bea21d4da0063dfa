"""Collision handling.

Kernels (``bvh``, ``traverse``, ``proximity``, ``ccd``, ``tritri``,
``impulses``, ``response``, ``friction``, ``imagespace``, ``mesh_query``):
AABB hierarchies, stack-based traversal, vertex-face / edge-edge proximity,
continuous collision detection, triangle-triangle intersection, contact and
friction responses.  Pure array code (numpy + numba): no MPI, no PETSc, no
configuration.  ``colliders`` holds body geometry and motion; ``contact``
is the one module that decides how a step treats contact, on top of the
kernels and of the distributed detector (``parallel/collide.py``: replicated
global BVH, task stacks exchanged between ranks, EG07 tutorial Part 1 §5.8).
"""
