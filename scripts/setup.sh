#!/usr/bin/env bash
# Installs every Debian 12 package drillbif needs to build, test and benchmark.
# Idempotent: packages already installed are skipped, so a second run costs a dpkg query only.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libeigen3-dev libsundials-dev libsqlite3-dev libpqxx-dev postgresql libspdlog-dev libfmt-dev
  libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev
  libssl-dev libcpp-httplib-dev libmicrohttpd-dev libutfcpp-dev prometheus-cpp-dev openssl
  gnuplot-nox python3-yaml docker-compose
  clang libclang-rt-14-dev
  nodejs npm chromium
)

# A package counts as present when installed, or when an installed package provides it (e.g.
# NodeSource's nodejs provides npm and conflicts with Debian's).
# (The list is read whole first: grep -q leaving early would fail the pipe under pipefail.)
installed_provides=$(dpkg-query -W -f='${db:Status-Abbrev} ${Provides}\n' 2>/dev/null | grep '^ii' || true)
provided() {
  grep -qE "[ ,]$1( \(|,|$)" <<< "$installed_provides"
}

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" &&
     ! provided "$p"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

echo "setup: installing ${missing[*]}" >&2
sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
