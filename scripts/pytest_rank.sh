#!/usr/bin/env bash
# One rank of the MPI test run: rank 0 reports on the terminal; the other ranks
# write to out/tests/rank-N.log, shown only if that rank fails.
set -uo pipefail
rank=${OMPI_COMM_WORLD_RANK:-0}
if [ "$rank" = 0 ]; then
  exec "$@"
fi
mkdir -p out/tests
log=out/tests/rank-$rank.log
"$@" > "$log" 2>&1
code=$?
if [ $code -ne 0 ]; then
  echo "---- rank $rank failed (exit $code); its log: ----" >&2
  tail -n 80 "$log" >&2
fi
exit $code
