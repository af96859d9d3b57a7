#!/usr/bin/env bash
# Saves screenshots of the dashboard into docs/figures/dashboard-*.png: starts drillbif-server
# (build/server/drillbif-server) on free ports with a temporary store and a token, submits a
# trace, a continuation, an optimum, an optimum map (queried from its panel), a simulation and a
# sweep from the page's forms in headless Chromium (puppeteer-core from build/web, as the browser
# tests), and captures each plot and the whole page. Needs a build (scripts/build.sh); takes about half a minute.
set -euo pipefail
cd "$(dirname "$0")/.."

build_dir=${BUILD_DIR:-build}
export DRILLBIF_SERVER_BINARY="$build_dir/server/drillbif-server"
export DRILLBIF_WEB_MODULES="$build_dir/web"
for needed in "$DRILLBIF_SERVER_BINARY" "$DRILLBIF_WEB_MODULES/node_modules/puppeteer-core"; do
  if [ ! -e "$needed" ]; then
    echo "screenshots.sh: $needed is missing: build first (scripts/build.sh)" >&2
    exit 1
  fi
done
mkdir -p docs/figures
node web/test/screenshots.mjs
