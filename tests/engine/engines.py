"""The CuraEngines the engine tier slices with: Debian 12's 4.13 on the host, 5.0 in a trixie chroot.

`ENGINES` names them; `engine(version)` gives what `curaengine.slice_models` needs to run one
(`executable=`, `resources=`).  A version that cannot run makes the tests that need it FAIL.

CuraEngine 5.0 exists only in Debian trixie, so it runs in a chroot (``/srv/trixie``, or
``$DELAUNAY_CURA5_ROOT``) built by ``scripts/cura5_chroot.sh``.  ``engine("5.0")`` builds or
refreshes that chroot itself when it is incomplete and we are root (once per process; set
``DELAUNAY_NO_APT=1`` to forbid it), then writes a small wrapper script whose command line is the
engine's: it rewrites every argument starting with the chroot's root (and ``CURA_ENGINE_SEARCH_PATH``)
to the path inside and runs the chroot's CuraEngine in the same working folder.  The host's ``/tmp``
is bind-mounted onto the chroot's ``/tmp``, so models, G-code and pytest's tmp dirs under ``/tmp``
have the same path on both sides.  ``resources`` is the chroot's Cura 5.0 resources folder: the
setting formulas are evaluated on the host with Cura 5.0's own definitions.

Example
-------
>>> e = engine("5.0")
>>> curaengine.slice_models([("star.stl", {})], {}, "/tmp/x/star.gcode", engine=e.executable,
...                         resources=e.resources, cwd="/tmp/x")
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass

from DelaunayInfill.curaengine import CuraEngineError


@dataclass(frozen=True)
class Engine:
    """One CuraEngine: pass ``executable`` and ``resources`` to ``curaengine.slice_models``."""

    version: str  # "4.13" or "5.0"
    executable: str | None = None  # None: the host's CuraEngine on PATH
    resources: str | None = None  # None: the host's Cura resources


ENGINES = ("4.13", "5.0")

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SETUP_SCRIPT = os.path.join(REPO, "scripts", "cura5_chroot.sh")
DEFAULT_ROOT = "/srv/trixie"
#: where the wrapper is written; under /tmp, so it also survives a fresh checkout
WRAPPER_CACHE = "/tmp/delaunay-cura5"
#: inside the chroot
RESOURCES_INSIDE = "/usr/share/cura/resources"


def chroot_root() -> str:
    """The trixie chroot's root folder (``$DELAUNAY_CURA5_ROOT`` or /srv/trixie)."""
    return os.path.abspath(os.environ.get("DELAUNAY_CURA5_ROOT") or DEFAULT_ROOT)


def engine(version: str) -> Engine:
    """The engine of that version, ready to slice; raises CuraEngineError when it cannot run."""
    if version == "4.13":
        return Engine("4.13")
    if version == "5.0":
        return _cura5(chroot_root())
    raise CuraEngineError(f"unknown CuraEngine version {version!r} (the tier knows {', '.join(ENGINES)})")


# --------------------------------------------------------------------------- CuraEngine 5.0 in the chroot


def _problems(root: str) -> list[str]:
    """What keeps the chroot's CuraEngine 5.0 from running (empty when it is ready)."""
    problems = []
    if not os.path.isfile(os.path.join(root, "usr/bin/CuraEngine")):
        problems.append(f"{root}/usr/bin/CuraEngine is missing")
    if not os.path.isfile(os.path.join(root, RESOURCES_INSIDE.lstrip("/"), "definitions", "fdmprinter.def.json")):
        problems.append(f"Cura 5.0's definitions are missing under {root}{RESOURCES_INSIDE}")
    mounted = _mount_points()
    for mount in ("proc", "dev", "tmp"):
        if os.path.join(root, mount) not in mounted:
            problems.append(f"{root}/{mount} is not mounted")
    return problems


def _mount_points() -> set[str]:
    """Every mount point of this process's view (os.path.ismount misses a bind mount within one file system)."""
    points = set()
    try:
        with open("/proc/self/mountinfo", encoding="utf-8") as f:
            for line in f:
                fields = line.split()
                if len(fields) > 4:
                    # mountinfo escapes blanks etc. as octal (\040)
                    points.add(re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), fields[4]))
    except OSError:
        pass
    return points


def _may_build() -> bool:
    """Whether this process may build the chroot: root, apt available, not forbidden."""
    return os.geteuid() == 0 and shutil.which("apt-get") is not None and not os.environ.get("DELAUNAY_NO_APT")


@functools.cache
def _run_setup(root: str) -> str:
    """Run scripts/cura5_chroot.sh once per process; returns its output (for error messages)."""
    print(f"engine tier: building/refreshing the trixie chroot at {root} (2-4 minutes the first time)",
          file=sys.stderr)
    proc = subprocess.run(["bash", SETUP_SCRIPT, "--root", root], capture_output=True, text=True, timeout=1800)
    output = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0:
        return f"{SETUP_SCRIPT} failed (exit {proc.returncode}): {output[-2000:]}"
    return output


def _bind_tmp(root: str) -> None:
    """Bind the host's /tmp onto the chroot's /tmp (pytest's tmp dirs must be the same path inside)."""
    target = os.path.join(root, "tmp")
    if target in _mount_points() or os.geteuid() != 0 or not os.path.isdir(target):
        return
    subprocess.run(["mount", "--bind", "/tmp", target], capture_output=True, check=False)


def _wrapper_text(root: str) -> str:
    """A bash script that runs the chroot's CuraEngine with the host's command line.

    Paths under `root` become the paths inside the chroot; the working folder is kept (``chroot``
    itself would change to ``/``), which works for folders under /tmp (shared) or under `root`.
    """
    return f"""#!/bin/bash
# CuraEngine 5.0 in the trixie chroot {root}; written by tests/engine/engines.py (do not edit).
set -u
ROOT={_shell_quote(root)}
if [ "$(id -u)" != 0 ]; then
  echo "[ERROR] CuraEngine 5.0 runs in the chroot $ROOT and needs root (chroot)" >&2; exit 2
fi
if [ ! -x "$ROOT/usr/bin/CuraEngine" ] || ! mountpoint -q "$ROOT/tmp"; then
  echo "[ERROR] the chroot $ROOT is not ready (CuraEngine or the /tmp bind mount missing): run scripts/cura5_chroot.sh" >&2
  exit 2
fi
# a host path under $ROOT is that path without the prefix inside the chroot
inside() {{
  case "$1" in
    "$ROOT") REPLY=/ ;;
    "$ROOT"/*) REPLY="${{1#"$ROOT"}}" ;;
    *) REPLY="$1" ;;
  esac
}}
args=()
for arg in "$@"; do inside "$arg"; args+=("$REPLY"); done
vars=()
if [ -n "${{CURA_ENGINE_SEARCH_PATH:-}}" ]; then
  IFS=: read -r -a parts <<< "$CURA_ENGINE_SEARCH_PATH"
  search=""
  for part in "${{parts[@]}}"; do inside "$part"; search="${{search:+$search:}}$REPLY"; done
  vars+=("CURA_ENGINE_SEARCH_PATH=$search")
fi
# chroot changes to /; keep the caller's folder when the chroot sees it (/tmp is shared)
inside "$PWD"; here="$REPLY"
if [ ! -d "$ROOT$here" ]; then
  echo "[WARNING] the working folder $PWD is not visible in the chroot $ROOT; relative paths will fail (work under /tmp)" >&2
  here=/
fi
exec /usr/sbin/chroot "$ROOT" /usr/bin/env -i -C "$here" HOME=/root USER=root LANG=C.UTF-8 PATH=/usr/bin:/bin \\
  "${{vars[@]}}" CuraEngine "${{args[@]}}"
"""


def _shell_quote(text: str) -> str:
    return "'" + text.replace("'", "'\\''") + "'"


def _write_wrapper(root: str) -> str:
    """Write the wrapper (atomically, only when it changed) and return its path."""
    folder = WRAPPER_CACHE if root == DEFAULT_ROOT else WRAPPER_CACHE + root.replace("/", "_")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "CuraEngine")
    text = _wrapper_text(root)
    try:
        with open(path, encoding="utf-8") as f:
            if f.read() == text and os.access(path, os.X_OK):
                return path
    except OSError:
        pass
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
    os.chmod(tmp, 0o755)
    os.replace(tmp, path)  # other processes may run the old one meanwhile: never a half-written file
    return path


def engine_version(executable: str | None) -> str:
    """The ``Cura_SteamEngine version X`` line of ``CuraEngine help`` (host engine when None)."""
    proc = subprocess.run([executable or "CuraEngine", "help"], capture_output=True, text=True, timeout=60)
    text = proc.stdout + proc.stderr
    return next((line.strip() for line in text.splitlines() if "version" in line.lower()), text.strip()[-500:])


@functools.cache
def _cura5(root: str) -> Engine:
    """CuraEngine 5.0 through the chroot at `root`, set up when needed; cached per process."""
    problems = _problems(root)
    setup_log = ""
    if problems and _may_build():
        setup_log = _run_setup(root)
        problems = _problems(root)
    if problems and os.path.isdir(os.path.join(root, "tmp")):
        _bind_tmp(root)  # e.g. built earlier, /tmp bind lost (reboot, --umount)
        problems = _problems(root)
    if problems:
        how = ("" if _may_build() else
               f" Build it as root: sudo bash {SETUP_SCRIPT} --root {root}"
               " (DELAUNAY_NO_APT=1 or not being root keeps the tier from doing it).")
        raise CuraEngineError(f"CuraEngine 5.0 (trixie chroot at {root}) cannot run: {'; '.join(problems)}.{how}"
                              + (f"\n{setup_log}" if setup_log else ""))
    wrapper = _write_wrapper(root)
    version = engine_version(wrapper)
    if "version 5.0" not in version:
        raise CuraEngineError(f"the chroot's CuraEngine at {root} is not 5.0: `{wrapper} help` says {version!r}")
    return Engine("5.0", wrapper, os.path.join(root, RESOURCES_INSIDE.lstrip("/")))
