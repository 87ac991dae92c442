#!/usr/bin/env bash
# Installs every Debian 12 package Sandtable builds, tests and runs with.
# Idempotent and non-interactive: when every package is already present it
# only checks and exits (well under a second). Needs root (or sudo) to install.
set -euo pipefail

PACKAGES=(
  # toolchain
  build-essential cmake ninja-build ccache pkg-config git clang-14 libclang-rt-14-dev
  clang-format
  # numerics
  libeigen3-dev libceres-dev
  # vision (contrib carries structured_light)
  libopencv-dev libopencv-contrib-dev
  # graphics: GL, EGL (Mesa llvmpipe for headless), windows, math, glTF
  libglfw3-dev libglm-dev libtinygltf-dev libstb-dev nlohmann-json3-dev
  libegl-dev libgl-dev libgles-dev libegl-mesa0 libgl1-mesa-dri mesa-utils xvfb xauth libx11-dev
  # world ray casting
  libembree-dev
  # protocol and transport
  libprotobuf-dev protobuf-compiler libzmq3-dev cppzmq-dev zlib1g-dev libczmq-dev
  # storage, devices
  libsqlite3-dev sqlite3 libusb-1.0-0-dev
  # command lines, HTTP, k-d trees
  libcli11-dev libcpp-httplib-dev libnanoflann-dev
  # MPCDI export: ZIP container, XML descriptor
  libminizip-dev libtinyxml2-dev
  # the lab's report.html (markdown with tables to HTML)
  libcmark-gfm-dev libcmark-gfm-extensions-dev
  # tests, benchmarks, plots
  libgtest-dev libgmock-dev libbenchmark-dev gnuplot-nox python3
  # sites across hosts: network namespaces, veth, sockets' backlogs (ip, ss)
  iproute2
  # the operator console's browser tests (tests/browser): headless Chromium, a font for its
  # screenshots; Node.js and npm are added below when no node is installed
  chromium fonts-dejavu-core
  # the rollout's test (tests/deploy): a systemd, an sshd and a system bus on each namespace host
  openssh-server dbus systemd
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
# Node.js for the browser tests: Debian's nodejs and npm, unless a node is already installed
# (another distribution of it, e.g. with its own npm).
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  missing+=(nodejs npm)
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
else
  echo "install-deps: installing ${#missing[@]} packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

# The browser tests' npm packages (tests/browser/package-lock.json: playwright-core, which
# drives the Chromium above), installed once and again when the lock file changes.
browser_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/tests/browser"
stamp="$browser_dir/node_modules/.sandtable-lock"
if ! cmp -s "$browser_dir/package-lock.json" "$stamp" 2>/dev/null; then
  echo "install-deps: npm packages for tests/browser"
  (cd "$browser_dir" && npm ci --no-audit --no-fund --loglevel=error)
  cp "$browser_dir/package-lock.json" "$stamp"
fi
echo "install-deps: done"
