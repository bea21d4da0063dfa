#!/usr/bin/env bash
# Set up if needed, then run a scene (default: the bundled default scene) on 2 ranks.
# Usage: scripts/run.sh [SCENE.yaml] [distcloth run options...]
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
"$here/scripts/setup.sh"
ranks=${DISTCLOTH_RANKS:-2}
if [ $# -eq 0 ]; then
    # the demo: run again, it replaces its own previous result (any other
    # scene refuses to overwrite a result unless given --overwrite)
    echo "run.sh: the default scene; replacing its previous result if there is one" >&2
    exec "$here/scripts/mpiexec.sh" "$ranks" "$here/.venv/bin/distcloth" run \
        "$here/configs/default.yaml" --overwrite
fi
scene=$1
shift
exec "$here/scripts/mpiexec.sh" "$ranks" "$here/.venv/bin/distcloth" run "$scene" "$@"
