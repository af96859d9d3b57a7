#!/usr/bin/env bash
# The accuracy-versus-time report (docs/accuracy.md), in one command: builds (scripts/build.sh,
# Release), runs the bench/accuracy_*_bench programs with JSON output into build/accuracy/, and
# regenerates docs/accuracy.md and docs/figures/accuracy_*.png from that run
# (scripts/accuracy_report.py, gnuplot). Takes about two minutes on the project's 2-core machine. CI
# builds these benchmarks but never runs this.
#   ./scripts/accuracy.sh
set -euo pipefail
cd "$(dirname "$0")/.."

# gnuplot renders the figures (scripts/setup.sh installs it too).
if ! command -v gnuplot > /dev/null; then
  sudo_cmd=()
  [ "$(id -u)" -ne 0 ] && sudo_cmd=(sudo)
  "${sudo_cmd[@]}" apt-get update
  "${sudo_cmd[@]}" apt-get install -y --no-install-recommends gnuplot-nox
fi

bash scripts/build.sh

out=build/accuracy
rm -rf "$out"
mkdir -p "$out"
for stage in simulation orbit continuation curve outputs; do
  echo "accuracy.sh: running accuracy_${stage}_bench" >&2
  "build/bench/accuracy_${stage}_bench" --benchmark_out="$out/accuracy_${stage}.json" \
    --benchmark_out_format=json
done

python3 scripts/accuracy_report.py "$out"
echo "accuracy.sh: wrote docs/accuracy.md and docs/figures/accuracy_*.png" >&2
