"""Partitioning and per-rank layout; the only package that imports MPI (mpi4py)."""
