#!/usr/bin/env bash
# The whole test suite, installing what it needs (the README's test command; .ci/run calls it).
#
#   bash scripts/test.sh            all tiers
#   bash scripts/test.sh unit       unit + property tests only (four dependency sets)
#
# Tiers:
#   unit    pytest tests/ (not engine, not gui) on four dependency sets:
#           current pins, the oldest pins Cura brings that have Python 3.11 wheels
#           (numpy 1.23.5, scipy 1.9.3, with shapely 1.8.5 and with shapely 2.0.1), and the
#           newest: the trixie chroot's Python 3.13 / numpy 2.2 / scipy 1.15 / shapely 2.1
#           (scripts/unit_newest.sh; the chroot is built by scripts/cura5_chroot.sh)
#   engine  tests/engine: real CuraEngine 4.13 slices (and 5.0 in a trixie chroot,
#           scripts/cura5_chroot.sh), processed and checked independently
#   gui     tests/gui: the real Cura 4.13 under Xvfb loads the plugin, slices, saves
#   gui5    tests/gui/test_gui5_*.py: the same in the real Cura 5.0 (PyQt6) of the trixie chroot
# A tier that cannot run fails; nothing is skipped.  Ends with one line "tests: N passed, M failed".
set -u
cd "$(dirname "$0")/.."
ROOT="$PWD"
WHAT="${1:-all}"
PY="${PYTHON:-python3}"
VENVS="$ROOT/.venvs"
RESULTS="$ROOT/test-artifacts/junit"
rm -rf "$RESULTS"; mkdir -p "$RESULTS"
FAILED_STEPS=()

log() { printf '\n=== %s ===\n' "$*"; }

need_apt() {
  local missing=()
  for pkg in "$@"; do dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg"); done
  [ ${#missing[@]} -eq 0 ] && return 0
  log "apt-get install ${missing[*]}"
  local sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
  $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

make_venv() {  # make_venv NAME PIP-ARGS...
  local dir="$VENVS/$1"; shift
  local stamp="$dir/.installed"
  local want="$*"
  if [ ! -x "$dir/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    log "venv $(basename "$dir"): $want"
    rm -rf "$dir"
    "$PY" -m venv "$dir" || return 1
    "$dir/bin/python" -m pip install -q --upgrade pip >/dev/null || return 1
    "$dir/bin/python" -m pip install -q "$@" || return 1
    echo "$want" > "$stamp"
  fi
  # the project itself, editable, without touching the pinned dependencies
  "$dir/bin/python" -m pip install -q --no-deps --no-build-isolation -e "$ROOT" >/dev/null 2>&1 \
    || "$dir/bin/python" -m pip install -q --no-deps -e "$ROOT" >/dev/null || return 1
}

run_pytest() {  # run_pytest LABEL VENV ARGS...
  local label="$1" venv="$2"; shift 2
  log "pytest [$label] $*"
  # the venv's bin first: tests run the `delaunay-infill` console script of this checkout, not one
  # that happens to be installed elsewhere on the machine
  PATH="$VENVS/$venv/bin:$PATH" "$VENVS/$venv/bin/python" -m pytest -q -p no:cacheprovider \
    --junitxml="$RESULTS/$label.xml" "$@"
  local rc=$?
  if [ $rc -ne 0 ]; then FAILED_STEPS+=("$label (exit $rc)"); fi
}

TEST_DEPS=(pytest hypothesis matplotlib manifold3d)
CURRENT=(numpy scipy shapely)
OLDEST_S18=(numpy==1.23.5 scipy==1.9.3 shapely==1.8.5)
OLDEST_S20=(numpy==1.23.5 scipy==1.9.3 shapely==2.0.1)

# Debian's python3 makes virtual environments only with python3-venv (ensurepip) installed
"$PY" -c "import ensurepip, venv" 2>/dev/null || need_apt python3-venv || FAILED_STEPS+=("apt-get install python3-venv")
make_venv current "${CURRENT[@]}" "${TEST_DEPS[@]}" || FAILED_STEPS+=("venv current")
UNIT=(tests -m "not engine and not gui" --ignore=tests/engine --ignore=tests/gui)
run_pytest unit-current current "${UNIT[@]}"
make_venv oldest-shapely18 "${OLDEST_S18[@]}" "${TEST_DEPS[@]}" "matplotlib<3.9" || FAILED_STEPS+=("venv oldest-shapely18")
run_pytest unit-oldest-shapely18 oldest-shapely18 "${UNIT[@]}"
make_venv oldest-shapely20 "${OLDEST_S20[@]}" "${TEST_DEPS[@]}" "matplotlib<3.9" || FAILED_STEPS+=("venv oldest-shapely20")
run_pytest unit-oldest-shapely20 oldest-shapely20 "${UNIT[@]}"

# Cura 5.0, CuraEngine 5.0 and the newest Python stack (3.13, numpy 2.2, scipy 1.15, shapely 2.1) live in
# a Debian trixie chroot (Debian 12 has Cura 4.13 only): build or refresh it (2-4 minutes the first
# time, about a second after that). The unit tier runs on its Python; the engine tier slices with both
# engines; the Cura 5.0 GUI tier runs there.
SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
log "trixie chroot with Cura 5.0 and CuraEngine 5.0 (scripts/cura5_chroot.sh)"
$SUDO bash scripts/cura5_chroot.sh || FAILED_STEPS+=("cura5_chroot.sh (Cura 5.0 chroot)")
log "pytest [unit-newest] on the chroot's Python 3.13 (scripts/unit_newest.sh)"
$SUDO bash scripts/unit_newest.sh "$RESULTS/unit-newest.xml" "${UNIT[@]}" || FAILED_STEPS+=("unit-newest (exit $?)")

if [ "$WHAT" = all ]; then
  need_apt cura-engine cura xvfb xauth imagemagick python3-zeroconf python3-pip iproute2 xdotool || FAILED_STEPS+=("apt-get install")
  # tests/engine and the real-CuraEngine tests beside the unit tests (marked engine, left out above)
  run_pytest engine current tests -m engine --ignore=tests/gui
  run_pytest gui current tests/gui --ignore-glob='*/test_gui5_*'
  # the same GUI checks in the real Cura 5.0 (PyQt6) of the trixie chroot built above
  run_pytest gui-cura5 current tests/gui/test_gui5_plugin.py tests/gui/test_gui5_regions.py tests/gui/test_gui5_paint.py
fi

# One closing line over every run.
"$VENVS/current/bin/python" - "$RESULTS" <<'PYEOF'
import glob, sys, xml.etree.ElementTree as ET
passed = failed = skipped = 0
for path in glob.glob(sys.argv[1] + "/*.xml"):
    for suite in ET.parse(path).getroot().iter("testsuite"):
        tests, fail, err, skip = (int(suite.get(k, 0)) for k in ("tests", "failures", "errors", "skipped"))
        passed += tests - fail - err - skip
        failed += fail + err
        skipped += skip
print(f"\ntests: {passed} passed, {failed} failed" + (f", {skipped} skipped" if skipped else ""))
PYEOF
if [ ${#FAILED_STEPS[@]} -ne 0 ]; then
  printf 'FAILED: %s\n' "${FAILED_STEPS[@]}"
  exit 1
fi
exit 0
