#!/usr/bin/env bash
# Idempotent setup for wpbench on Debian 12 (bookworm), CPU only.
#  1. system packages: Mesa's lavapipe Vulkan driver from bookworm-backports
#     (SAPIEN's renderer needs descriptor indexing, which bookworm's Mesa 22 lacks),
#  2. a virtualenv in .venv with torch 2.13.0 (CPU build) and wpbench installed editable.
# Re-running it changes nothing that is already in place.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
VENV="${WPBENCH_VENV:-$here/.venv}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  # Without a terminal (CI, make from a script) sudo must not wait for a password.
  if [ -t 0 ]; then SUDO="sudo"; else SUDO="sudo -n"; fi
fi
export DEBIAN_FRONTEND=noninteractive

log() { printf '[setup] %s\n' "$*" >&2; }

# --- system packages -------------------------------------------------------
# Derive the backports source from the Debian mirror already configured here;
# no host is written in this script.
enable_backports() {
  local list=/etc/apt/sources.list.d/wpbench-backports.list
  [ -f "$list" ] && return 0
  local mirror=""
  if compgen -G "/etc/apt/sources.list.d/*.sources" >/dev/null; then
    mirror=$(awk '/^URIs:/ {for (i=2;i<=NF;i++) if ($i !~ /security/) {print $i; exit}}' \
             /etc/apt/sources.list.d/*.sources 2>/dev/null | head -n1)
  fi
  if [ -z "$mirror" ] && [ -f /etc/apt/sources.list ]; then
    mirror=$(awk '$1=="deb" && $0 !~ /security/ {for (i=2;i<=NF;i++) if ($i ~ /^[a-z]+:\/\//) {print $i; exit}}' \
             /etc/apt/sources.list | head -n1)
  fi
  if [ -z "$mirror" ]; then
    log "no Debian mirror found in /etc/apt/sources.list(.d); configure one, then re-run"
    exit 1
  fi
  log "enabling bookworm-backports on $mirror"
  echo "deb $mirror bookworm-backports main" | $SUDO tee "$list" >/dev/null
}

need_vulkan() {
  # lavapipe from backports is Mesa >= 24; bookworm's own is 22.
  local v
  v=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)
  case "$v" in ""|22.*) return 0 ;; *) return 1 ;; esac
}

need_venv_module() {
  # Debian splits `venv`/ensurepip into python3-venv; a fresh install lacks it.
  local py="${PYTHON:-python3.11}"
  command -v "$py" >/dev/null 2>&1 || py=python3
  ! command -v "$py" >/dev/null 2>&1 || ! "$py" -c "import ensurepip, venv" >/dev/null 2>&1
}

if command -v apt-get >/dev/null 2>&1; then
  if [ ! -x "$VENV/bin/python" ] && need_venv_module; then
    log "installing python3 and python3-venv"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq python3 python3-venv >/dev/null
  fi
  if need_vulkan || ! dpkg -s libvulkan1 >/dev/null 2>&1; then
    enable_backports
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq -t bookworm-backports mesa-vulkan-drivers libvulkan1 >/dev/null
    log "installed $(dpkg-query -W -f='mesa-vulkan-drivers ${Version}' mesa-vulkan-drivers)"
  fi
else
  log "apt-get not found: install a Vulkan driver (Mesa lavapipe >= 24) yourself"
fi

# --- python environment ----------------------------------------------------
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
pip() { "$VENV/bin/python" -m pip "$@"; }
if [ ! -x "$VENV/bin/python" ]; then
  log "creating virtualenv $VENV"
  "$PY" -m venv "$VENV"
  # Only for a new venv: re-runs must not need the network.
  pip install -q --upgrade pip >/dev/null
fi
# torch first: the CPU build of 2.13.0 lies on this machine's disk; any other
# request would download a multi-GB CUDA build.
if ! "$VENV/bin/python" -c "import torch, sys; sys.exit(torch.__version__.split('+')[0] != '2.13.0')" 2>/dev/null; then
  log "installing torch==2.13.0 (CPU)"
  pip install -q "torch==2.13.0"
fi
stamp="$VENV/.wpbench-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  log "installing wpbench and its dependencies"
  pip install -q -e ".[dev]"
  touch "$stamp"
fi
# numpy 1 for the panda executor's mplib planner process (wpbench/sim/arm_planner_env.py).
"$VENV/bin/python" -m wpbench.sim.arm_planner_env >/dev/null
log "ready: $VENV/bin/wpbench"
