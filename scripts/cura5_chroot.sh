#!/usr/bin/env bash
# Build or refresh a Debian trixie chroot holding CuraEngine 5.0 and Cura 5.0 (Debian 12 has 4.13 only).
#
#   bash scripts/cura5_chroot.sh [--root DIR]            build / refresh (default /srv/trixie), as root
#   bash scripts/cura5_chroot.sh [--root DIR] --umount   undo the mounts (tmp, dev/pts, dev, sys, proc)
#
# Every step is skipped when it is already done, so a second run takes about a second:
#   1. debootstrap (minbase trixie) when DIR/usr/bin/apt-get is missing; debootstrap itself is
#      installed on the host with apt-get when missing
#   2. mount proc, sys, dev, dev/pts, and bind the host's /tmp onto DIR/tmp: a path under /tmp is then
#      the same file inside and outside the chroot (pytest's tmp dirs, the G-code the engine writes)
#   3. apt-get install the packages below that are missing (the optional ones only if trixie has them)
# Ends with one line saying what is installed; exits non-zero with a message when it cannot build.
# The engine tier (tests/engine/engines.py) runs CuraEngine 5.0 through this chroot.
# Never `rm -rf` DIR while it is mounted (run --umount first): DIR/tmp is the host's /tmp.
set -u

ROOT=/srv/trixie
MIRROR="${CURA5_MIRROR:-http://deb.debian.org/debian}"
# qt6-svg-plugins: Debian's cura does not depend on it, yet Cura 5.0 shows no SVG icon without it
REQUIRED=(cura cura-engine xvfb xauth python3-shapely python3-scipy python3-numpy imagemagick
          x11-utils xdotool qt6-svg-plugins)
OPTIONAL=(python3-pytest python3-hypothesis python3-matplotlib)
# the order --umount takes: nested mounts first
MOUNTS=(tmp dev/pts dev sys proc)
UMOUNT=0
ARGS="$*"
# debootstrap, chroot and mount live in sbin, which a non-login root shell may lack on its PATH
PATH="$PATH:/usr/local/sbin:/usr/sbin:/sbin"

usage() { sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; }
die() { echo "cura5_chroot: $*" >&2; exit 1; }
note() { echo "cura5_chroot: $*" >&2; }

while [ $# -gt 0 ]; do
  case "$1" in
    --root) [ $# -ge 2 ] || die "--root needs a folder"; ROOT="${2%/}"; shift 2 ;;
    --umount) UMOUNT=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "cura5_chroot: unknown argument $1" >&2; usage >&2; exit 2 ;;
  esac
done
[ -n "$ROOT" ] && [ "$ROOT" != / ] || die "refusing to use / as the chroot root"
[ "$(id -u)" = 0 ] || die "must run as root (debootstrap, mount and chroot need it): sudo bash $0 $ARGS"

# Run a command inside the chroot with a clean environment (the host's variables mean nothing there).
in_root() {
  chroot "$ROOT" /usr/bin/env -i HOME=/root USER=root LANG=C.UTF-8 DEBIAN_FRONTEND=noninteractive \
    PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin "$@"
}

# apt on the host may be busy (another test run installing cura-engine): wait for its lock.
host_apt() { DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 "$@"; }

unmount_all() {
  local m rc=0
  for m in "${MOUNTS[@]}"; do
    # a loop: a mount may be stacked (mounted twice by hand); stop at the first failure
    while mountpoint -q "$ROOT/$m"; do
      umount "$ROOT/$m" || { note "cannot unmount $ROOT/$m (in use?)"; rc=1; break; }
    done
  done
  return $rc
}

ensure_debootstrap() {
  command -v debootstrap >/dev/null && return 0
  command -v apt-get >/dev/null || die "debootstrap is missing and there is no apt-get to install it"
  note "installing debootstrap on the host"
  host_apt update -qq >/dev/null || note "apt-get update failed; trying the install anyway"
  host_apt install -y -qq --no-install-recommends debootstrap >/dev/null \
    || die "cannot install debootstrap on the host (apt-get install debootstrap failed)"
}

ensure_base() {
  [ -x "$ROOT/usr/bin/apt-get" ] && return 0
  ensure_debootstrap
  note "debootstrap --variant=minbase trixie $ROOT (about half a minute)"
  mkdir -p "$ROOT" || die "cannot create $ROOT"
  debootstrap --variant=minbase trixie "$ROOT" "$MIRROR" >"$ROOT.debootstrap.log" 2>&1 \
    || die "debootstrap failed (log: $ROOT.debootstrap.log, last lines: $(tail -n 3 "$ROOT.debootstrap.log" | tr '\n' ' '))"
  [ -x "$ROOT/usr/bin/apt-get" ] || die "debootstrap finished but $ROOT/usr/bin/apt-get is missing"
  rm -f "$ROOT.debootstrap.log"
}

# mount_one TARGET TYPE-OR-BIND SOURCE
mount_one() {
  local target="$ROOT/$1" how="$2" source="$3"
  mountpoint -q "$target" && return 0
  mkdir -p "$target" || die "cannot create $target"
  if [ "$how" = bind ]; then
    mount --bind "$source" "$target" || die "cannot bind-mount $source on $target"
  else
    mount -t "$how" "$source" "$target" || die "cannot mount $how on $target"
  fi
}

ensure_mounts() {
  mount_one proc proc proc
  mount_one sys sysfs sys
  mount_one dev bind /dev
  mount_one dev/pts bind /dev/pts
  # the host's /tmp, so that /tmp/x is the same file for the host and for the engine in the chroot
  mount_one tmp bind /tmp
  # apt inside needs name resolution; the chroot's own resolv.conf is empty
  cp -L /etc/resolv.conf "$ROOT/etc/resolv.conf" 2>/dev/null || true
}

installed() { in_root dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }

# A package trixie has (a candidate in the chroot's package lists).
available() {
  local candidate
  candidate="$(in_root apt-cache policy "$1" 2>/dev/null | sed -n 's/^ *Candidate: //p')"
  [ -n "$candidate" ] && [ "$candidate" != "(none)" ]
}

ensure_packages() {
  local p missing=() optional=() updated=0
  for p in "${REQUIRED[@]}"; do installed "$p" || missing+=("$p"); done
  for p in "${OPTIONAL[@]}"; do installed "$p" || optional+=("$p"); done
  [ ${#missing[@]} -eq 0 ] && [ ${#optional[@]} -eq 0 ] && return 0
  note "apt-get update in the chroot"
  in_root apt-get update -qq >/dev/null || die "apt-get update failed inside $ROOT (network? mirror $MIRROR)"
  for p in "${optional[@]}"; do
    if available "$p"; then missing+=("$p"); else note "$p is not in trixie: left out"; fi
  done
  if [ ${#missing[@]} -gt 0 ]; then
    note "installing ${missing[*]} (a minute or two)"
    in_root apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null \
      || die "apt-get install ${missing[*]} failed inside $ROOT"
  fi
  in_root apt-get clean
  for p in "${REQUIRED[@]}"; do installed "$p" || die "$p is still not installed in $ROOT"; done
}

summary() {
  local versions engine
  versions="$(in_root dpkg-query -W -f='${Package} ${Version}, ' cura cura-engine python3 python3-numpy \
    python3-scipy python3-shapely "${OPTIONAL[@]}" 2>/dev/null)"
  engine="$(in_root CuraEngine help 2>&1 | grep -i -m1 'version' | sed 's/^ *//')"
  [ -n "$engine" ] || die "CuraEngine does not run inside $ROOT"
  echo "trixie chroot ready at $ROOT (/tmp shared): ${versions%, }; $engine"
}

if [ "$UMOUNT" = 1 ]; then
  unmount_all || exit 1
  echo "trixie chroot at $ROOT: unmounted"
  exit 0
fi
ensure_base
ensure_mounts
ensure_packages
summary
