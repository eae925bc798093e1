#!/usr/bin/env bash
# System libraries the Python wheels need. open3d needs libusb-1.0 at import time.
set -euo pipefail
if ldconfig -p 2>/dev/null | grep -q 'libusb-1\.0\.so'; then
  exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "installing libusb-1.0-0 (needed by open3d) with apt-get"
  apt-get update -qq >/dev/null
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
  exit 0
fi
echo "error: open3d needs the system library libusb-1.0. Install it (Debian/Ubuntu: 'sudo apt-get install libusb-1.0-0') and run make again." >&2
exit 1
