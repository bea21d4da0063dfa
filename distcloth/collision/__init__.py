"""Collision handling.

BVH kernels (``bvh``, ``traverse``, ``proximity``, ``ccd``, ``tritri``):
AABB hierarchies, stack-based traversal, vertex-face / edge-edge proximity,
continuous collision detection and triangle-triangle intersection.  Pure
array code (numpy + numba): no MPI, no PETSc, no configuration; the
distributed driver (replicated global BVH, task stacks exchanged between
ranks, seed 000 Part 1 §5.8) is built on top of them.
"""
