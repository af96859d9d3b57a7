#!/usr/bin/env bash
# Builds everything into build/: installs the Debian packages (scripts/setup.sh), configures with
# CMake + Ninja and builds with all cores.
#
# Extra CMake arguments come from DRILLBIF_CMAKE_ARGS (split on whitespace), e.g.
#   DRILLBIF_CMAKE_ARGS="-DDRILLBIF_SANITIZE=ON" ./scripts/build.sh
# Options default to their documented values on every run (a sanitized build is not silently
# kept by a later plain run); anything in DRILLBIF_CMAKE_ARGS overrides them.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/setup.sh

build_dir=build
read -r -a extra_args <<< "${DRILLBIF_CMAKE_ARGS:-}"

# A build/ configured by hand with another generator cannot be reconfigured with Ninja: drop its
# cache (build/ is generated; sources are never touched).
if [ -f "$build_dir/CMakeCache.txt" ] &&
   ! grep -q '^CMAKE_GENERATOR:INTERNAL=Ninja$' "$build_dir/CMakeCache.txt"; then
  echo "build.sh: $build_dir/ was configured with another generator; reconfiguring with Ninja" >&2
  rm -rf "$build_dir/CMakeCache.txt" "$build_dir/CMakeFiles"
fi

cmake -S . -B "$build_dir" -G Ninja \
  -DCMAKE_BUILD_TYPE=Release -DDRILLBIF_SANITIZE=OFF \
  "${extra_args[@]}"
cmake --build "$build_dir" --parallel "$(nproc)"
