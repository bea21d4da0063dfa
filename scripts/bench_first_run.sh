#!/usr/bin/env bash
# Whole-process times of the README's run command in a fresh clone: the first
# call (venv, editable install, numba warm-up, the run) and a second one (the
# run alone, kernels cached).  Debian packages are assumed installed already.
# Usage: scripts/bench_first_run.sh [REPOSITORY]   (default: this checkout)
set -euo pipefail
src=${1:-$(cd "$(dirname "$0")/.." && pwd)}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
git clone -q "$src" "$tmp/clone"
for call in first second; do
  start=$(date +%s.%N)
  "$tmp/clone/scripts/run.sh" >"$tmp/$call.log" 2>&1
  end=$(date +%s.%N)
  run=$(grep -o 'completed in [0-9.]* s' "$tmp/$call.log" | grep -o '[0-9.]*' | head -1)
  printf '%-6s call of scripts/run.sh: %6.1f s whole process, of which the run %s s\n' \
    "$call" "$(awk "BEGIN{print $end - $start}")" "$run"
done
