#!/usr/bin/env bash
# Set up if needed, then run a scene (default: the bundled default scene) on 2 ranks.
# Usage: scripts/run.sh [SCENE.yaml] [distcloth run options...]
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
"$here/scripts/setup.sh"
scene=${1:-$here/configs/default.yaml}
[ $# -gt 0 ] && shift
ranks=${DISTCLOTH_RANKS:-2}
exec "$here/scripts/mpiexec.sh" "$ranks" "$here/.venv/bin/distcloth" run "$scene" "$@"
