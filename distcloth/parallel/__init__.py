"""Everything that talks MPI: the communicator wrapper, partitioning and the
per-rank layout, the ghost exchange, the distributed collision detector and
its work stealing.  The only package that imports mpi4py."""
