#!/usr/bin/env bash
# Install vgn-service with every extra (service, simulator, dev tools) into the current Python.
# Open3D needs the system library libusb-1.0; it is installed here when missing (apt-based systems).
set -euo pipefail
cd "$(dirname "$0")"

if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  if command -v apt-get >/dev/null 2>&1; then
    sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    echo "installing libusb-1.0-0 (needed by open3d)"
    $sudo apt-get update -qq && $sudo apt-get install -y -qq libusb-1.0-0 >/dev/null
  else
    echo "warning: libusb-1.0 is missing; install it with your package manager (open3d needs it)" >&2
  fi
fi

# torch is pinned (==2.13.0) in pyproject.toml so pip takes the CPU wheel, not the CUDA stack.
python3 -m pip install --quiet --disable-pip-version-check -e ".[all,dev]"
