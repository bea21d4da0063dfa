#!/usr/bin/env bash
# The project's MPI launcher: Open MPI as root, oversubscription allowed (more
# ranks than the 2 cores), idle ranks yield the core instead of spinning,
# and --quiet: Open MPI's multi-line banners (after a rank exits non-zero,
# say) would bury distcloth's one-line errors.  DISTCLOTH_MPI_VERBOSE=1 keeps them.
# Usage: scripts/mpiexec.sh N command [args...]
set -euo pipefail
n=$1; shift
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_mpi_yield_when_idle=1
export OMPI_MCA_rmaps_base_oversubscribe=1
quiet=--quiet
[ "${DISTCLOTH_MPI_VERBOSE:-0}" != 0 ] && quiet=
exec mpiexec $quiet --oversubscribe -n "$n" "$@"
