#!/usr/bin/env bash
# System libraries the Python packages need but do not ship: open3d loads libusb-1.0 at import.
set -euo pipefail
if ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
  echo "installing Debian package libusb-1.0-0 (needed by open3d)" >&2
  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
else
  echo "error: libusb-1.0 is missing (open3d needs it); install it, e.g. 'sudo apt-get install libusb-1.0-0'" >&2
  exit 1
fi
