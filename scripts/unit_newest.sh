#!/usr/bin/env bash
# The unit tier on the newest stack Cura users have: Debian trixie's Python 3.13, numpy 2.2,
# scipy 1.15, shapely 2.1 (what Cura 5.0 runs on there), inside the chroot that
# scripts/cura5_chroot.sh builds.  Called by scripts/test.sh; run as root.
#
#   bash scripts/unit_newest.sh JUNIT.xml [pytest args...]
#
# The checkout is copied under /tmp (the host's /tmp is the chroot's /tmp), the chroot's own
# python3 runs pytest there with the project on PYTHONPATH, and a `delaunay-infill` wrapper on PATH
# stands for the console script the CLI tests run.  Exits with pytest's status.
set -u
cd "$(dirname "$0")/.."
ROOT=/srv/trixie
JUNIT="${1:?usage: unit_newest.sh JUNIT.xml [pytest args...]}"; shift
PATH="$PATH:/usr/local/sbin:/usr/sbin:/sbin"
[ -x "$ROOT/usr/bin/python3" ] || { echo "unit_newest: no chroot at $ROOT (scripts/cura5_chroot.sh builds it)" >&2; exit 1; }
mountpoint -q "$ROOT/tmp" || { echo "unit_newest: $ROOT/tmp is not the host's /tmp (run scripts/cura5_chroot.sh)" >&2; exit 1; }
COPY=/tmp/delaunay-unit-newest
rm -rf "$COPY"; mkdir -p "$COPY/bin"
# the tracked files and the working tree's changes, without venvs, artifacts or caches
tar -C "$PWD" --exclude=.git --exclude=.venvs --exclude=test-artifacts --exclude=__pycache__ \
  --exclude='*.egg-info' --exclude=delaunay-demo -cf - . | tar -C "$COPY" -xf -
cat > "$COPY/bin/delaunay-infill" <<EOF
#!/usr/bin/python3
import sys
sys.path.insert(0, "$COPY")
from DelaunayInfill.cli import main
sys.exit(main())
EOF
chmod +x "$COPY/bin/delaunay-infill"
mkdir -p "$(dirname "$JUNIT")"
chroot "$ROOT" /usr/bin/env -i HOME=/root USER=root LANG=C.UTF-8 CI="${CI:-}" MPLBACKEND=Agg \
  PYTHONPATH="$COPY" PATH="$COPY/bin:/usr/local/bin:/usr/bin:/bin" \
  sh -c "cd '$COPY' && python3 -c 'import sys, numpy, scipy, shapely; print(\"unit tier on Python\", sys.version.split()[0], \"numpy\", numpy.__version__, \"scipy\", scipy.__version__, \"shapely\", shapely.__version__)' && exec python3 -m pytest -q -p no:cacheprovider -c tests/pytest.ini --junitxml='$COPY/junit.xml' \"\$@\"" sh "$@"
status=$?
cp "$COPY/junit.xml" "$JUNIT" 2>/dev/null || true
exit $status
