#!/usr/bin/env bash
# The demo on the embedded default (the README's demo command):
# processes the bundled CuraEngine G-code (five-point star with the paper's Figure 10 densities,
# H-bracket) and writes processed G-code, layer pictures and a summary to ./delaunay-demo.
# Extra arguments go to `delaunay-infill demo` (e.g. --reslice to slice the bundled STLs first
# when CuraEngine is installed).
set -eu
cd "$(dirname "$0")/.."
VENV=".venvs/demo"
if [ ! -x "$VENV/bin/delaunay-infill" ]; then
  if ! python3 -c "import ensurepip, venv" 2>/dev/null; then
    # Debian's python3 makes virtual environments only with python3-venv installed
    sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
    $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends python3-venv >/dev/null
  fi
  python3 -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -e '.[plot]'
fi
exec "$VENV/bin/delaunay-infill" demo -o delaunay-demo "$@"
