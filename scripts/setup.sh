#!/usr/bin/env bash
# Idempotent set-up: system packages (libLLVM for Dr.Jit, Mesa EGL/GL, glslang, SPIRV-Tools
# and SPIRV-Cross for the engine targets, headless Chromium for the WebGL 2 viewer's tests,
# npm where Node.js is missing), the virtual environment at .venv/ with the project installed,
# and node_modules/ with the JavaScript libraries package-lock.json pins (three.js).
set -euo pipefail
cd "$(dirname "$0")/.."

SYSTEM_PACKAGES=(libllvm19 libegl1 libegl-mesa0 libgl1-mesa-dri mesa-vulkan-drivers glslang-tools spirv-tools spirv-cross spirv-headers
    chromium-headless-shell)
missing=()
for p in "${SYSTEM_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
command -v npm >/dev/null || missing+=(npm)
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing system packages: ${missing[*]}"
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null || PY=python3
if ! "$PY" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
    echo "setup: Python 3.11 is required (found $("$PY" --version 2>&1)); set PYTHON=/path/to/python3.11" >&2
    exit 1
fi
if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv"
    "$PY" -m venv .venv
fi
stamp=.venv/.installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "setup: installing the project into .venv"
    .venv/bin/pip install -q --upgrade pip
    .venv/bin/pip install -q -e '.[dev]'
    touch "$stamp"
fi
npm_stamp=node_modules/.package-lock.json
if [ ! -f "$npm_stamp" ] || [ package-lock.json -nt "$npm_stamp" ]; then
    echo "setup: installing the JavaScript libraries into node_modules (npm ci)"
    npm ci --no-audit --no-fund --loglevel=error >/dev/null
fi
