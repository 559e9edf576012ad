#!/usr/bin/env bash
# Install what the GUI test tier needs, when missing: Debian's Cura 4.13 (with its
# CuraEngine, Uranium, PyQt5, numpy, scipy, shapely 1.8.5), Xvfb, xauth, ImageMagick
# (/usr/bin/import for screenshots), python3-zeroconf (else UM3NetworkPrinting pops up
# "could not be loaded") and python3-pip (to put trimesh 3.9.36 on Cura's PYTHONPATH).
# iproute2: `ip` brings up the loopback of the network namespace each Cura session runs in.
# xdotool: the real mouse drags and clicks of the region and paint tests.
# Needs root or sudo. Exit status 0 when everything is there afterwards.
set -euo pipefail
PACKAGES=(cura cura-engine xvfb xauth imagemagick python3-zeroconf python3-pip iproute2 xdotool)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "GUI tier dependencies present"
  exit 0
fi
echo "installing: ${missing[*]}"
SUDO=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || { echo "need root (or sudo) to apt-get install ${missing[*]}" >&2; exit 1; }
  SUDO="sudo -n"
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
