#!/usr/bin/env bash
# Set up harp station on a fresh Debian 12 machine with Python 3.11:
# system packages (Aravis + GObject introspection for GenICam cameras), a
# virtual environment in .venv, and the project with its test dependencies.
set -euo pipefail
cd "$(dirname "$0")/.."
APT_PKGS="python3-venv python3-dev gcc pkg-config libgirepository1.0-dev libcairo2-dev gir1.2-aravis-0.8 libaravis-0.8-0 aravis-tools postgresql chromium"
# the real consumers of the exports, for the tests (run under /usr/bin/python3): mrcal, the ROS camera_info
# parser and image_geometry; OpenEXR's exrheader. Without recommends (they would pull in Qt and VTK).
CONSUMER_PKGS="python3-mrcal python3-camera-calibration-parsers python3-image-geometry openexr"
if ! dpkg -s $APT_PKGS >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $APT_PKGS >/dev/null
fi
if ! dpkg -s $CONSUMER_PKGS >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $CONSUMER_PKGS >/dev/null
fi
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[test]'
echo "harp station installed in .venv (activate with: . .venv/bin/activate)"
