#!/usr/bin/env bash
# The main job, end to end through the service:
#   1. builds everything (scripts/build.sh: Debian packages first, then CMake + Ninja);
#   2. starts drillbif-server on 127.0.0.1 (free ports, --port-file) with its SQLite store in a
#      temporary directory (or in $DRILLBIF_DB, e.g. DRILLBIF_DB=./drillbif.db, kept afterwards);
#   3. runs the headline continuation through the client,
#        drillctl --server 127.0.0.1:PORT continue --param b --min 0 --max 0.2
#      (the reference orbit, MODEL.md's parameters), and prints its special points and the ROP
#      optimum along the branch (the stable ROP maximum: ROP ~0.5387 at b ~0.16382);
#   4. asks the server for the robust ROP optimum in (omega, a) on a small box (drillctl optimum),
#      then for another margin over the same curves (which the server reuses);
#   5. computes an optimum map of that box over the weight on bit b (5 cells, drillctl
#      optimum-map) and asks for the optimum at a b between cells: answered from the map,
#      interpolated and verified there;
#   6. lists the server's jobs and stops the server with SIGTERM (graceful shutdown).
# Build output and the server's log go to stderr; stdout is the report. Takes ~6 s once built.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh >&2
for binary in build/client/drillctl build/server/drillbif-server; do
  if [ ! -x "$binary" ]; then
    echo "run.sh: $binary was not built" >&2
    exit 1
  fi
done

work=$(mktemp -d "${TMPDIR:-/tmp}/drillbif_run.XXXXXX")
db=${DRILLBIF_DB:-$work/drillbif.db}
server_pid=
cleanup() {
  if [ -n "$server_pid" ] && kill -0 "$server_pid" 2>/dev/null; then
    kill -TERM "$server_pid" 2>/dev/null || true
    wait "$server_pid" 2>/dev/null || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT

build/server/drillbif-server --host 127.0.0.1 --grpc-port 0 --http-port 0 --db "$db" \
  --port-file "$work/ports" --log-level warn >&2 &
server_pid=$!
# The port file (gRPC port, then HTTP port) appears once the server serves.
for _ in $(seq 1 200); do
  [ -s "$work/ports" ] && break
  if ! kill -0 "$server_pid" 2>/dev/null; then
    echo "run.sh: drillbif-server exited at start" >&2
    exit 1
  fi
  sleep 0.05
done
if [ ! -s "$work/ports" ]; then
  echo "run.sh: drillbif-server did not start within 10 s" >&2
  exit 1
fi
grpc_port=$(sed -n 1p "$work/ports")
http_port=$(sed -n 2p "$work/ports")
export DRILLBIF_SERVER="127.0.0.1:$grpc_port"
drillctl=build/client/drillctl

echo "drillbif-server: gRPC 127.0.0.1:$grpc_port, HTTP 127.0.0.1:${http_port:-?}, store $db"
echo
echo "== $drillctl --server $DRILLBIF_SERVER continue --param b --min 0 --max 0.2 --format csv"
"$drillctl" continue --param b --min 0 --max 0.2 --format csv > "$work/continue.csv"
points=$(grep -vc '^#' "$work/continue.csv" || true)
echo "branch: $((points - 1)) points; special points (kind, b, ROP, stable):"
grep '^# ' "$work/continue.csv" |
  sed -E 's/^# ([A-Z_0-9]+) value=([^ ]+) rop=([^ ]+) power=[^ ]+ stable=([a-z]+).*/  \1 \2 \3 \4/' |
  awk '{ printf "  %-16s b = %.8f  ROP = %.4f  %s\n", $1, $2, $3, ($4 == "true" ? "stable" : "unstable") }'
echo
# The ROP optimum of the branch: the largest ROP among its stable ROP maxima.
grep '^# ROP_MAX ' "$work/continue.csv" | grep 'stable=true' |
  sed -E 's/^# ROP_MAX value=([^ ]+) rop=([^ ]+) .*/\1 \2/' |
  sort -k2,2 -g | tail -1 |
  awk '{ printf "ROP optimum along the b-branch: ROP = %.4f at b = %.5f (stable period-1 orbit)\n", $2, $1 }'
echo
echo "== $drillctl --server $DRILLBIF_SERVER optimum --params omega,a --min 0.05,0.25 --max 0.15,0.6 --margin 0.01,0.02 --grid 21,21 --format csv"
"$drillctl" optimum --params omega,a --min 0.05,0.25 --max 0.15,0.6 --margin 0.01,0.02 \
  --grid 21,21 --format csv | tee "$work/optimum.csv"
# The row: a,b,omega,xi,g,phi0,rop,margin1,margin2,...
awk -F, 'NR == 2 && $7 != "" {
  printf "robust ROP optimum at b = %s: ROP = %.4f at omega = %s, a = %s (margins %.4f, %.4f)\n",
         $2, $7, $3, $1, $8, $9 }' "$work/optimum.csv"
echo
# Another margin over the same curves and grid: the server reuses them (curvesReused,
# regionReused) and answers in milliseconds.
echo "== $drillctl --server $DRILLBIF_SERVER optimum --params omega,a --min 0.05,0.25 --max 0.15,0.6 --margin 0.02,0.04 --grid 21,21"
"$drillctl" optimum --params omega,a --min 0.05,0.25 --max 0.15,0.6 --margin 0.02,0.04 \
  --grid 21,21 > "$work/optimum2.json"
for field in rop curvesReused regionReused traceSeconds regionSeconds querySeconds; do
  grep -m1 "^ *\"$field\":" "$work/optimum2.json" | tr -d ' ,\n'
  echo -n ' '
done
echo
echo
# An optimum map over the weight on bit b, then the optimum at a b between its cells: answered
# from the map (interpolated from the neighbouring cells, verified at that b), not computed.
map_flags="--params omega,a --min 0.05,0.25 --max 0.15,0.6 --margin 0.01,0.02 --grid 21,21"
echo "== $drillctl --server $DRILLBIF_SERVER optimum-map $map_flags --over b --from 0.14 --to 0.16 --steps 5 --format csv"
# shellcheck disable=SC2086
"$drillctl" optimum-map $map_flags --over b --from 0.14 --to 0.16 --steps 5 --format csv |
  grep -v '^#' | sort -t, -k1,1 -g |
  awk -F, 'NR > 1 { printf "  b = %-7.4g %s  ROP = %.4f at omega = %s, a = %s\n", $1, $2, $9, $5, $3 }'
echo
echo "== $drillctl --server $DRILLBIF_SERVER optimum $map_flags --b 0.1475 --format csv"
# shellcheck disable=SC2086
"$drillctl" optimum $map_flags --b 0.1475 --format csv 2> "$work/query.err" > "$work/query.csv"
sed -E 's/^drillctl: //' "$work/query.err"
awk -F, 'NR == 2 && $7 != "" {
  printf "optimum at b = %s (from the map): ROP = %.4f at omega = %s, a = %s\n", $2, $7, $3, $1 }' \
  "$work/query.csv"
echo
echo "== $drillctl --server $DRILLBIF_SERVER jobs list --format csv"
"$drillctl" jobs list --format csv | cut -d, -f1-7

kill -TERM "$server_pid"
status=0
wait "$server_pid" || status=$?
server_pid=
if [ "$status" -ne 0 ]; then
  echo "run.sh: drillbif-server exited with status $status after SIGTERM" >&2
  exit 1
fi
echo
echo "drillbif-server stopped (SIGTERM, exit 0)."
