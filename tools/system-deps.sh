#!/usr/bin/env bash
# System packages the Python packages need but do not ship, installed with apt-get (as root) when missing:
#   libusb-1.0-0  open3d loads libusb-1.0 at import (required)
#   chromium      headless browser that opens the HTML report in tests/test_report.py (optional: without it
#                 that test builds the report but skips opening it)
set -euo pipefail
need_usb=0
need_chromium=0
ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0' || need_usb=1
command -v chromium >/dev/null || command -v chromium-browser >/dev/null || need_chromium=1
if [ "$need_usb" = "0" ] && [ "$need_chromium" = "0" ]; then
  exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
  apt-get update -qq
  if [ "$need_usb" = "1" ]; then
    echo "installing Debian package libusb-1.0-0 (needed by open3d)" >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
  fi
  if [ "$need_chromium" = "1" ]; then
    echo "installing Debian package chromium (opens the HTML report in the tests)" >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null ||
      echo "warning: could not install chromium; the report test will skip opening the report" >&2
  fi
  exit 0
fi
if [ "$need_usb" = "1" ]; then
  echo "error: libusb-1.0 is missing (open3d needs it); install it, e.g. 'sudo apt-get install libusb-1.0-0'" >&2
  exit 1
fi
echo "warning: chromium is missing (the report test skips opening the report); e.g. 'sudo apt-get install chromium'" >&2
