#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/, docs/fuzzing.md) into build-fuzz/ with Clang and
# -fsanitize=fuzzer,address,undefined, then runs each for DRILLBIF_FUZZ_SECONDS (default 20) over
# a copy of its seed corpus (fuzz/corpus/<target>/): new inputs go to the copy, never into the
# repository. Prints executions, time, coverage and findings per target; exits non-zero on any
# finding (crash, sanitizer report, violated invariant, timeout, out of memory), whose input is
# kept in build-fuzz/findings/<target>/.
#
#   ./scripts/fuzz.sh                                  # every target, 20 s each
#   DRILLBIF_FUZZ_SECONDS=300 ./scripts/fuzz.sh        # the longer run of docs/fuzzing.md
#   ./scripts/fuzz.sh sweep_request_fuzz               # some targets only
#
# Targets run DRILLBIF_FUZZ_JOBS at a time (default: the number of cores). Extra CMake arguments
# come from DRILLBIF_FUZZ_CMAKE_ARGS; ccache is used when installed.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${DRILLBIF_FUZZ_SECONDS:-20}
jobs=${DRILLBIF_FUZZ_JOBS:-$(nproc)}
build_dir=build-fuzz
all_targets=(rest_request_fuzz simulate_request_fuzz sweep_request_fuzz continue_request_fuzz
             trace_request_fuzz optimum_request_fuzz)
if [ $# -gt 0 ]; then targets=("$@"); else targets=("${all_targets[@]}"); fi

bash scripts/setup.sh

read -r -a extra_args <<< "${DRILLBIF_FUZZ_CMAKE_ARGS:-}"
if command -v ccache > /dev/null; then extra_args=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache "${extra_args[@]}"); fi
build_start=$(date +%s)
# -O1 with line tables: libFuzzer's usual trade between speed and readable reports. No NDEBUG:
# assertions (Eigen's too) stay on.
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_CXX_COMPILER=clang++ -DDRILLBIF_FUZZ=ON \
  -DDRILLBIF_BUILD_TESTS=OFF -DDRILLBIF_BUILD_BENCH=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" "${extra_args[@]}" > /dev/null
cmake --build "$build_dir" --target "${targets[@]}" --parallel "$(nproc)"
echo "fuzz: built ${#targets[@]} targets in $(( $(date +%s) - build_start )) s"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
findings_root="$build_dir/findings"

# Runs one target; its log goes to $work/<target>.log.
run_target() {
  local target=$1
  local corpus="$work/corpus/$target" findings="$findings_root/$target"
  rm -rf "$findings"  # A finding of an earlier run is not one of this run.
  mkdir -p "$corpus" "$findings"
  if [ -d "fuzz/corpus/$target" ]; then cp -r "fuzz/corpus/$target/." "$corpus/"; fi
  local dict=fuzz/dict/kind_request.dict
  if [ "$target" = rest_request_fuzz ]; then dict=fuzz/dict/rest_request.dict; fi
  # -timeout: one input taking 10 s is a hang (a plan runs in microseconds); -rss_limit_mb: the
  # request checks hold kilobytes, so 2 GB is a leak or a runaway allocation.
  "$build_dir/fuzz/$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -max_len=4096 -dict="$dict" -print_final_stats=1 -artifact_prefix="$findings/" \
    "$corpus" > "$work/$target.log" 2>&1
}

status=0
pids=()
names=()
for target in "${targets[@]}"; do
  run_target "$target" &
  pids+=($!)
  names+=("$target")
  if [ ${#pids[@]} -ge "$jobs" ]; then
    wait "${pids[0]}" || true
    pids=("${pids[@]:1}")
  fi
done
for pid in "${pids[@]}"; do wait "$pid" || true; done

printf '%-24s %12s %8s %10s %8s %8s %8s %9s\n' target executions seconds execs/s cov ft corpus findings
for target in "${targets[@]}"; do
  log="$work/$target.log"
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  time_s=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$log" | tail -1)
  final=$(grep -E '^#[0-9]+' "$log" | tail -1 || true)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<< "$final")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<< "$final")
  corp=$(sed -n 's/.* corp: \([0-9]*\).*/\1/p' <<< "$final")
  found=$(find "$findings_root/$target" -type f | wc -l)
  rate=-
  if [ -n "$execs" ] && [ -n "$time_s" ] && [ "$time_s" -gt 0 ]; then rate=$(( execs / time_s )); fi
  printf '%-24s %12s %8s %10s %8s %8s %8s %9s\n' "$target" "${execs:--}" "${time_s:--}" "$rate" \
    "${cov:--}" "${ft:--}" "${corp:--}" "$found"
  if [ "$found" -gt 0 ] || [ -z "$execs" ]; then
    status=1
    echo "fuzz: $target FAILED; its log:" >&2
    grep -v -E '^#[0-9]+' "$log" | tail -40 >&2
    find "$findings_root/$target" -type f -printf '  finding: %p\n' >&2
  fi
done
if [ "$status" -ne 0 ]; then
  echo "fuzz: findings above (reproduce: $build_dir/fuzz/<target> <finding>)" >&2
  exit 1
fi
echo "fuzz: ${#targets[@]} targets, ${seconds} s each, no finding"
