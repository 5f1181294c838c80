#!/usr/bin/env bash
# Install vgn-service into the current Python with the exact versions CI tested (requirements/).
#   bash install.sh         the service and the simulator: what `vgn-client clear-scene --sim` needs
#   bash install.sh --dev   every extra with the test tools (Chromium for the browser test, HAProxy for the fleet's): CI's
# Open3D needs a few system libraries (libusb-1.0 above all); they are installed here when
# missing (apt-based systems).
set -euo pipefail
cd "$(dirname "$0")"

dev=0
for arg in "$@"; do
  case "$arg" in
    --dev) dev=1 ;;
    -h|--help) sed -n 2,4p "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "install.sh: unknown option $arg (use --dev for the test tools)" >&2; exit 2 ;;
  esac
done

# apt-get, waiting (up to 10 minutes) for another apt run that holds the package lock instead of failing.
apt_install() {
  local sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  if ! $sudo apt-get -o DPkg::Lock::Timeout=0 check >/dev/null 2>&1; then
    echo "another apt run holds the package lock: waiting for it (up to 10 minutes)"
  fi
  $sudo apt-get -o DPkg::Lock::Timeout=600 update -qq &&
    $sudo apt-get -o DPkg::Lock::Timeout=600 install -y -qq "$@" >/dev/null
}

# System libraries open3d links against, with their Debian packages.
needed=(libusb-1.0.so.0:libusb-1.0-0 libGL.so.1:libgl1 libEGL.so.1:libegl1 libX11.so.6:libx11-6
        libudev.so.1:libudev1 libidn2.so.0:libidn2-0 libgomp.so.1:libgomp1)
missing=()
for entry in "${needed[@]}"; do
  ldconfig -p 2>/dev/null | grep -q "${entry%%:*}" || missing+=("${entry##*:}")
done
if [ ${#missing[@]} -gt 0 ]; then
  if command -v apt-get >/dev/null 2>&1; then
    echo "installing ${missing[*]} (needed by open3d)"
    apt_install "${missing[@]}"
  else
    echo "warning: missing system libraries for open3d: ${missing[*]}; install them with your package manager" >&2
  fi
fi

# HAProxy for the fleet tests (tests/fleet/: replicas behind the proxy `vgn-client serve --replicas` runs).
if [ "$dev" = 1 ] && ! command -v haproxy >/dev/null 2>&1; then
  if command -v apt-get >/dev/null 2>&1; then
    echo "installing haproxy (the fleet tests)"
    apt_install haproxy
  else
    echo "warning: haproxy is missing; the fleet tests will fail" >&2
  fi
fi

# Headless Chromium for the viewer's browser test (tests/service/test_viewer.py fails without it).
if [ "$dev" = 1 ] && { ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; }; then
  if command -v apt-get >/dev/null 2>&1; then
    echo "installing chromium and chromium-driver (the viewer's browser test)"
    apt_install chromium chromium-driver
  else
    echo "warning: chromium and chromedriver are missing; the viewer's browser test will fail" >&2
  fi
fi

# The lock pins every package (requirements/README.md; tests/test_lock.py checks it is current
# and installed). torch is pinned (==2.13.0): where pip is configured with a local CPU wheel
# (find-links, as on our development machines) it takes that; elsewhere add
# PIP_EXTRA_INDEX_URL=https://download.pytorch.org/whl/cpu to get the CPU build, not CUDA.
# ray and runtimes: the --ray tests and the runtime comparison's tests run in CI too; docs: CI
# builds the documentation site (mkdocs build --strict); ros: the ROS 2 bridge's tests (tests/ros/);
# realsense: the RealSense capture example's test (tests/test_docs_examples.py), without a camera.
if [ "$dev" = 1 ]; then
  lock=requirements/full.txt extras=all,dev,docs,ray,runtimes,ros,realsense
else
  lock=requirements/main.txt extras=service,sim
fi
python3 -m pip install --quiet --disable-pip-version-check -c "$lock" -e ".[$extras]"
