#!/usr/bin/env bash
# Regenerates the example figures of the docs (docs/figures/*.png; docs/guide.md, README.md) with drillctl --local and
# drillctl plot (needs gnuplot: scripts/setup.sh installs it). About 5 s. Usage:
#   scripts/figures.sh [BUILD_DIR]     (default: build)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
drillctl="${1:-$root/build}/client/drillctl"
out="$root/docs/figures"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

# One-parameter: the reference orbit continued in b over [0, 0.2] (fold, period doublings,
# grazings, ROP maxima).
"$drillctl" --local continue --param b --min 0 --max 0.2 -o "$work/continue.json"
"$drillctl" plot "$work/continue.json" -o "$out/continue_b.png"

# Two-parameter: a small (omega, a) box around the reference orbit with its stability region and the
# robust optimum.
box=(--params omega,a --min 0.05,0.25 --max 0.15,0.6)
"$drillctl" --local trace "${box[@]}" --grid 101,101 -o "$work/trace.json"
"$drillctl" --local optimum "${box[@]}" --margin 0.01,0.02 --grid 101,101 -o "$work/optimum.json"
"$drillctl" plot "$work/trace.json" --optimum "$work/optimum.json" -o "$out/trace_omega_a.png"

# Brute force: b swept up and down over [0.1, 0.2].
"$drillctl" --local sweep --param b --min 0.1 --max 0.2 --steps 101 --direction both \
  --samples 50 -o "$work/sweep.json"
"$drillctl" plot "$work/sweep.json" --param b -o "$out/sweep_b.png"

echo "figures: wrote $out/continue_b.png, trace_omega_a.png, sweep_b.png" >&2
