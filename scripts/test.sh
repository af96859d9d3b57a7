#!/usr/bin/env bash
# Builds everything (scripts/build.sh) and runs the whole test suite with CTest.
# Extra arguments go to ctest, e.g. ./scripts/test.sh -R EventLocation  or  -L flow
# A run that finds no test fails (--no-tests=error): an empty suite must not look green.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh
ctest --test-dir build --output-on-failure -j2 --timeout 600 --no-tests=error "$@"
