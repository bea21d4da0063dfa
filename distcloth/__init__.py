"""distcloth: a distributed-memory cloth simulator on MPI and PETSc."""
