#!/usr/bin/env bash
# Copied from the project's shared reference kit, unchanged apart from this line.
# Installs Mitsuba 3 (the reference renderer we compare against) into a
# virtualenv, plus the LLVM library its CPU backend needs.
# Usage: setup-mitsuba.sh [VENV_DIR]   (default ~/.cache/penumbra-mitsuba/venv)
# Afterwards: export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
set -euo pipefail
venv=${1:-$HOME/.cache/penumbra-mitsuba/venv}
if ! ldconfig -p | grep -q 'libLLVM.so.19'; then
  apt-get update -qq && apt-get install -y -qq libllvm19
fi
python3 -m venv "$venv"
"$venv/bin/pip" install -q --upgrade pip
"$venv/bin/pip" install -q mitsuba==3.9.1 drjit==1.5.0 numpy imageio
echo "Mitsuba ready: $venv/bin/python (set DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1)"
