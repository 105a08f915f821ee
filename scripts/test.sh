#!/usr/bin/env bash
# Every test, on a fresh machine: installs the peers the tests run against (iproute2, linuxptp,
# socat, libusb and chromium from apt where missing; the Python peers into .venv), then runs
# `cargo test --workspace`. Arguments go to cargo test (e.g. `scripts/test.sh -p starc-livox`).
set -euo pipefail
cd "$(dirname "$0")/.."

need=()
command -v ip >/dev/null || need+=(iproute2)
command -v ptp4l >/dev/null || [ -x /usr/sbin/ptp4l ] || need+=(linuxptp)
command -v socat >/dev/null || need+=(socat)
python3 -c 'import venv' 2>/dev/null || need+=(python3-venv)
# Open3D's wheel links libusb-1.0 (the alignment peers).
ldconfig -p | grep -c 'libusb-1.0.so.0' >/dev/null || need+=(libusb-1.0-0)
# The browser view's screenshot test (view/tests/view_chromium.rs).
command -v chromium >/dev/null || need+=(chromium)
if [ ${#need[@]} -gt 0 ]; then
  echo "installing: ${need[*]}"
  sudo_=()
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "need root (or sudo) to apt-get install ${need[*]}" >&2; exit 1; }
    sudo_=(sudo)
  fi
  "${sudo_[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_[@]}" apt-get install -y -qq "${need[@]}"
fi

if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/pip install -q --disable-pip-version-check -r tests/peers/requirements.txt

cargo test --workspace "$@"
