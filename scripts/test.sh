#!/usr/bin/env bash
# Set up if needed, then run the whole test suite under mpiexec -n 2.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
"$here/scripts/setup.sh"
cd "$here"
exec "$here/scripts/mpiexec.sh" 2 "$here/scripts/pytest_rank.sh" "$here/.venv/bin/python" -m pytest -q --color=no "$@" tests
