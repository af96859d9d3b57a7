#!/usr/bin/env bash
# Builds everything (scripts/build.sh) and runs the whole test suite with CTest.
# Extra arguments go to ctest, e.g. ./scripts/test.sh -R EventLocation  or  -L flow
# A run that finds no test fails (--no-tests=error): an empty suite must not look green.
# First the fuzz targets run for a short, fixed time (scripts/fuzz.sh; DRILLBIF_FUZZ=0 skips
# them), so that ctest's summary stays the last lines of the run.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh
if [ "${DRILLBIF_FUZZ:-1}" != 0 ]; then bash scripts/fuzz.sh; fi
ctest --test-dir build --output-on-failure -j2 --timeout 600 --no-tests=error "$@"
