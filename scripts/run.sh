#!/usr/bin/env bash
# Builds everything (scripts/build.sh), then runs the headline simulation in-process:
#   build/client/drillctl --local simulate [args...]
# Build output goes to stderr, so stdout is only drillctl's JSON (./scripts/run.sh | jq .).
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh >&2
if [ ! -x build/client/drillctl ]; then
  echo "run.sh: build/client/drillctl was not built (no client/*.cc sources?)" >&2
  exit 1
fi
exec build/client/drillctl --local simulate "$@"
