"""A body that moves: skeleton, skinning weights, skinning (linear blend and
dual quaternion), motion capture and its retargeting to the body.

Kernels only: arrays in, arrays out, no MPI.  Coordinates are the body
file's own (y up, metres) until a collider places them in the scene.
"""
