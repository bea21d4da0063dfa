#!/usr/bin/env bash
# The project's MPI launcher: Open MPI as root, oversubscription allowed (more
# ranks than the 2 cores), idle ranks yield the core instead of spinning.
# Usage: scripts/mpiexec.sh N command [args...]
set -euo pipefail
n=$1; shift
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_mpi_yield_when_idle=1
export OMPI_MCA_rmaps_base_oversubscribe=1
exec mpiexec --oversubscribe -n "$n" "$@"
