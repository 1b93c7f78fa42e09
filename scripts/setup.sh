#!/usr/bin/env bash
# Set up clfx on a fresh Debian 12 machine: system OpenCL (PoCL) + a .venv with the project.
#
#   scripts/setup.sh            runtime + test extras (idempotent; fast when already done)
#
# Installs, only where missing:
#   - Debian packages: pocl-opencl-icd (the CPU OpenCL driver), ocl-icd-opencl-dev (headers,
#     needed to build pyvkfft), python3-venv, clinfo, oclgrind (the OpenCL simulator that
#     tests/test_oclgrind.py runs every kernel under; registered with no ICD, so it never
#     becomes a render device).  Needs root or sudo; otherwise prints the
#     exact command to run and stops.
#   - .venv with clfx installed editable plus its [test] extras, and pyvkfft built from source
#     with its OpenCL backend (VKFFT_BACKEND=opencl).  Never PyPI's pocl-binary-distribution:
#     it fails on these CPUs ("unknown target CPU 'generic'").
#
# Quiet: one line per step on stderr; a step that fails shows its own output (the last lines,
# and where the whole log is).  The editable install is a plain path entry (pyproject's
# package-dir), so `import clfx` works from any folder, the clone's parent included.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
VENV=${VENV:-.venv}
APT_PKGS=(pocl-opencl-icd ocl-icd-opencl-dev ocl-icd-libopencl1 python3-venv clinfo oclgrind)

say() { printf 'clfx setup: %s\n' "$*" >&2; }

# Run a step's command with its output kept aside; on failure show it and stop.
quietly() {
  local log
  log=$(mktemp "${TMPDIR:-/tmp}/clfx-setup.XXXXXX")
  if "$@" >"$log" 2>&1; then
    rm -f "$log"
    return 0
  fi
  say "failed: $*"
  tail -n 40 "$log" >&2
  say "the whole output: $log"
  exit 1
}

missing_debs() {
  local p
  for p in "${APT_PKGS[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || echo "$p"
  done
}

install_system_packages() {
  command -v dpkg-query >/dev/null || { say "not a Debian system: install PoCL and the OpenCL headers yourself"; return 0; }
  local need
  need=$(missing_debs | tr '\n' ' ')
  [ -z "${need// }" ] && return 0
  local sudo=""
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null && sudo -n true 2>/dev/null; then sudo="sudo"; else
      say "missing Debian packages: $need"
      say "run:  sudo apt-get update && sudo apt-get install -y $need"
      exit 1
    fi
  fi
  say "installing Debian packages: $need"
  quietly $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  # shellcheck disable=SC2086
  quietly $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $need
}

create_venv() {
  if [ ! -x "$VENV/bin/python" ]; then
    say "creating $VENV"
    quietly "$PYTHON" -m venv "$VENV"
  fi
}

install_python_packages() {
  local stamp="$VENV/.clfx-installed" want
  want=$(cat pyproject.toml scripts/setup.sh | sha1sum | cut -c1-40)
  if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && "$VENV/bin/python" -c 'import clfx, pyvkfft.opencl' 2>/dev/null; then
    say "Python packages in $VENV: up to date"
    return 0
  fi
  say "installing Python packages into $VENV"
  quietly "$VENV/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip wheel setuptools
  quietly "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e '.[test]'
  if ! "$VENV/bin/python" -c 'import pyvkfft.opencl' 2>/dev/null; then
    say "building pyvkfft with its OpenCL backend (one-off, a few minutes)"
    quietly env VKFFT_BACKEND=opencl "$VENV/bin/python" -m pip install -q --disable-pip-version-check \
      --no-build-isolation pyvkfft
  fi
  echo "$want" > "$stamp"
}

install_system_packages
create_venv
install_python_packages
# PoCL keeps compiled kernels here; persistent so the next run starts warm.
export POCL_CACHE_DIR="${POCL_CACHE_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/clfx/pocl}"
mkdir -p "$POCL_CACHE_DIR"
if ! devices=$("$VENV/bin/clfx" devices 2>&1); then
  printf '%s\n' "$devices" >&2
  say "no usable OpenCL device (see above)"
  exit 1
fi
say "OpenCL device: $(printf '%s\n' "$devices" | sed -n 's/^\* //p' | head -n 1)"
