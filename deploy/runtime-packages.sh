#!/usr/bin/env bash
# Prints the Debian packages that hold the shared libraries the given binaries load (ldd), one
# per line: what a runtime image or host needs to run them, with no build tools. Used by the
# Dockerfile's build stage; also handy before installing the binaries on a plain Debian 12 host:
#   deploy/runtime-packages.sh build/server/drillbif-server build/client/drillctl
set -euo pipefail

if [ $# -eq 0 ]; then
  echo "usage: $0 BINARY..." >&2
  exit 2
fi

# What drillbif-server needs at run time, named as well as found by ldd below: its HTTP port
# (libmicrohttpd, which brings GnuTLS for HTTPS) and its metrics (prometheus-cpp's core library).
server_packages=(libmicrohttpd12 libprometheus-cpp-core1.0)

{
for binary in "$@"; do
  if [ "$(basename "$binary")" = drillbif-server ]; then
    printf '%s\n' "${server_packages[@]}"
  fi
done
for binary in "$@"; do
  ldd "$binary" | awk '/=> \// { print $3 }'
done | sort -u | while read -r lib; do
  real=$(readlink -f "$lib")
  # Debian 12 merges /lib into /usr/lib, but dpkg records each file under the path its package
  # ships it at: try the path, the resolved path, and both with and without the /usr prefix.
  package=
  for path in "$lib" "$real" "/usr$lib" "${real#/usr}"; do
    if owner=$(dpkg -S "$path" 2>/dev/null); then
      package=${owner%%:*}
      break
    fi
  done
  if [ -z "$package" ]; then
    echo "runtime-packages.sh: no package owns $lib" >&2
    exit 1
  fi
  echo "$package"
done
} | sort -u
