#!/usr/bin/env bash
# Ensure the Debian libraries for headless MuJoCo rendering (EGL, Mesa) are present; install them when missing.
set -euo pipefail
packages=(libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null; then
  echo "Headless rendering needs ${missing[*]} (EGL + Mesa). Got no apt-get on this machine. Install them with your package manager, or set MUJOCO_GL=osmesa with libosmesa6." >&2
  exit 1
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null && sudo -n true 2>/dev/null; then SUDO="sudo -n"; else
    echo "Headless rendering needs ${missing[*]}. Got no root rights to install them. Run: sudo apt-get install -y ${missing[*]}" >&2
    exit 1
  fi
fi
echo "Installing ${missing[*]} for headless MuJoCo rendering"
$SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -qq
$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
