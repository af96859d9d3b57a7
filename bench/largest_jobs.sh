#!/usr/bin/env bash
# The largest job of each kind that the DEFAULT limits admit, each run alone on a fresh
# drillbif-server (127.0.0.1, ports 0, its own temporary SQLite file), and what it costs the
# server: peak RSS (VmHWM of /proc/PID/status) against the idle server's, the run time (the
# operation's start_time to end_time) against the time estimated at submit, and the stored
# result (the db file and its WAL). For each kind the request one step larger is submitted too
# and must be refused at submit (RESOURCE_EXHAUSTED naming the limit); so is a 10^7-value sweep.
# Prints a markdown table (docs/service.md, "Memory of the largest accepted jobs").
#
#   bench/largest_jobs.sh [BUILD_DIR] [KIND...]     e.g. bench/largest_jobs.sh build trace
#
# Each request is the largest admitted with every field but one fixed, the boundary being proved
# by the pair: the request is accepted and the one a step larger refused. The time estimate is
# read from the refusal a server with a 1 ns time limit gives the same request.
set -euo pipefail

build=${1:-build}
shift || true
kinds=("$@")
[[ ${#kinds[@]} -gt 0 ]] || kinds=(simulate sweep-samples sweep-values continue trace optimum)
server_bin=$build/server/drillbif-server
[[ -x $server_bin ]] || { echo "no $server_bin: build drillbif-server first" >&2; exit 1; }

work=$(mktemp -d /tmp/drillbif_largest.XXXXXX)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT

# start_server DIR [FLAG...]: starts a server on DIR/jobs.db; sets server_pid and http_port.
start_server() {
  local dir=$1
  shift
  mkdir -p "$dir"
  "$server_bin" --grpc-port 0 --http-port 0 --db "$dir/jobs.db" --port-file "$dir/port" \
    --log-level warn "$@" 2>"$dir/server.log" &
  server_pid=$!
  pids+=("$server_pid")
  for _ in $(seq 200); do
    [[ -s $dir/port ]] && break
    sleep 0.05
  done
  http_port=$(sed -n 2p "$dir/port")
}

stop_server() {
  kill -TERM "$server_pid" 2>/dev/null || true
  wait "$server_pid" 2>/dev/null || true
}

vmhwm_kb() { awk '/^VmHWM/ {print $2}' "/proc/$1/status"; }
vmrss_kb() { awk '/^VmRSS/ {print $2}' "/proc/$1/status"; }

# submit KIND JSON -> prints "HTTP_STATUS BODY" (the body on one line).
submit() {
  local out
  out=$(curl -s -w '\n%{http_code}' -d "{\"request\": $2}" "127.0.0.1:$http_port/v1/jobs:$1")
  echo "$(tail -n 1 <<<"$out") $(head -n -1 <<<"$out" | tr -d '\n')"
}

# seconds_between T0 T1: RFC 3339 times (fractional seconds) -> seconds.
seconds_between() { echo "$(date -d "$2" +%s.%N) - $(date -d "$1" +%s.%N)" | bc; }

# The request of each row: "kind|request JSON|request one step larger|what binds".
# Defaults (jobs/registry.cc): 256 MB of results and 1 GB of memory per job; 300 s (simulate),
# 600 s (continue), 1800 s (sweep, trace, optimum).
request_of() {
  case $1 in
    simulate)
      # Result-bound: 40 B a Poincare sample against 256 MB -> 6.4e6 samples.
      echo 'simulate|{"samplePeriods": 6399999, "outputs": {"poincare": true}}|{"samplePeriods": 6400001, "outputs": {"poincare": true}}|max_result_bytes' ;;
    sweep-samples)
      # Memory-bound (4x the result): 1000 values of S samples, 40 S + 30 bytes each, against
      # 1 GB / 4 -> S = 6249.
      echo 'sweep|{"param": "b", "min": 0.0, "max": 0.2, "steps": 1000, "samplePeriods": 6249}|{"param": "b", "min": 0.0, "max": 0.2, "steps": 1000, "samplePeriods": 6250}|max_memory_bytes' ;;
    sweep-values)
      # Memory-bound with the most values: one sample and no transient a value, 70 B each,
      # against 1 GB / 4 -> 3571428 values.
      echo 'sweep|{"param": "b", "min": 0.0, "max": 0.2, "steps": 3571428, "transientPeriods": 0, "samplePeriods": 1}|{"param": "b", "min": 0.0, "max": 0.2, "steps": 3571429, "transientPeriods": 0, "samplePeriods": 1}|max_memory_bytes' ;;
    continue)
      # Memory-bound: ~20 kB a point against 1 GB -> 50000 steps; short steps so that the
      # branch really takes them.
      echo 'continue|{"param": "b", "min": 0.0, "max": 0.2, "direction": "INCREASING", "initialStep": 1e-6, "maxStep": 1e-6, "maxSteps": 50000}|{"param": "b", "min": 0.0, "max": 0.2, "direction": "INCREASING", "initialStep": 1e-6, "maxStep": 1e-6, "maxSteps": 50001}|max_memory_bytes' ;;
    trace)
      # Memory-bound: the small (omega, a) box's curves and a region grid of N x N nodes.
      echo "trace|{$SMALL_BOX, \"region\": {\"grid\": [$REGION_N, $REGION_N]}}|{$SMALL_BOX, \"region\": {\"grid\": [$REGION_N, $((REGION_N + 1))]}}|max_memory_bytes" ;;
    optimum)
      echo "optimum|{\"trace\": {$SMALL_BOX}, \"grid\": [$REGION_N, $REGION_N]}|{\"trace\": {$SMALL_BOX}, \"grid\": [$REGION_N, $((REGION_N + 1))]}|max_memory_bytes" ;;
    *) echo "unknown kind $1" >&2; exit 1 ;;
  esac
}
SMALL_BOX='"traceParams": ["omega", "a"], "min": [0.05, 0.25], "max": [0.15, 0.6]'
# The largest square region grid admitted with the small box's curves (jobs/trace_job.cc,
# RegionCost); the over-limit request adds one column.
REGION_N=${REGION_N:-1281}

# The time estimates: a server whose every kind has a 1 ns time limit refuses each request
# naming "about X of computing".
start_server "$work/probe" --workers 1 --job-limit simulate.seconds=1e-9 \
  --job-limit sweep.seconds=1e-9 --job-limit continue.seconds=1e-9 \
  --job-limit trace.seconds=1e-9 --job-limit optimum.seconds=1e-9
declare -A estimate
for row in "${kinds[@]}"; do
  IFS='|' read -r kind request _ _ <<<"$(request_of "$row")"
  estimate[$row]=$(submit "$kind" "$request" | grep -o 'about [^"]* of computing' |
    sed 's/about //; s/ of computing//' || echo "?")
done
stop_server

# A 10^7-value sweep, refused at submit by the default limits.
start_server "$work/huge"
huge=$(submit sweep '{"param": "b", "min": 0.0, "max": 0.2, "steps": 10000000}')
stop_server
echo "10^7-value sweep: HTTP ${huge%% *}: $(jq -r .message <<<"${huge#* }")" >&2

echo "| kind | request | binds | estimated time | run time | idle VmHWM | peak VmHWM | growth | RSS after | db + WAL | one step over |"
echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
for row in "${kinds[@]}"; do
  IFS='|' read -r kind request over binds <<<"$(request_of "$row")"
  dir=$work/$row
  start_server "$dir" --workers 1
  sleep 0.5  # let the idle server settle (threads started, optimum index loaded)
  idle=$(vmhwm_kb "$server_pid")
  answer=$(submit "$kind" "$request")
  if [[ ${answer%% *} != 200 ]]; then
    echo "| $row | \`$request\` | refused: $(jq -r .message <<<"${answer#* }") |"
    stop_server
    continue
  fi
  name=$(jq -r .name <<<"${answer#* }")
  while :; do
    op=$(curl -s "127.0.0.1:$http_port/v1/$name")
    [[ $(jq -r '.done // false' <<<"$op") == true ]] && break
    sleep 0.5
  done
  peak=$(vmhwm_kb "$server_pid")
  held=$(vmrss_kb "$server_pid")
  state=$(jq -r .metadata.state <<<"$op")
  run=$(seconds_between "$(jq -r .metadata.startTime <<<"$op")" "$(jq -r .metadata.endTime <<<"$op")")
  refused=$(submit "$kind" "$over")
  refusal="HTTP ${refused%% *}"
  if [[ ${refused%% *} != 200 ]]; then
    refusal="$refusal, names $(jq -r .message <<<"${refused#* }" | grep -o '(max_[a-z_]* of' | tr -d '(' | sed 's/ of$//' || echo '?')"
  fi
  stop_server
  db=$(cat "$dir"/jobs.db* | wc -c)
  printf '| %s | `%s` | %s | %s | %.1f s (%s) | %d MiB | %d MiB | %d MiB | %d MiB | %d MB | %s |\n' \
    "$row" "$request" "$binds" "${estimate[$row]}" "$run" "$state" $((idle / 1024)) \
    $((peak / 1024)) $(((peak - idle) / 1024)) $((held / 1024)) $((db / 1000000)) "$refusal"
done
