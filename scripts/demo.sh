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
  python3 -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -e '.[plot]'
fi
exec "$VENV/bin/delaunay-infill" demo -o delaunay-demo "$@"
