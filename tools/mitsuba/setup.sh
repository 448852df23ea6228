#!/usr/bin/env bash
# Sets up Mitsuba 3 for tools/mitsuba/ (converter, reference script, tests/mitsuba.rs and
# `cargo bench --bench harness -- peers`), in one command, from the repository root or
# anywhere:
#
#   tools/mitsuba/setup.sh
#
# 1. Debian's libllvm19: Mitsuba's llvm variant JIT-compiles through an LLVM shared library
#    (LLVM 15, Debian 12's default, crashes it). render.py finds it; DRJIT_LIBLLVM_PATH
#    overrides.
# 2. A virtualenv in .venv/ (git-ignored) with requirements.txt; the tests and the harness
#    look for .venv/bin/python first (FIRSTSHOT_PYTHON overrides).
set -euo pipefail
cd "$(dirname "$0")/../.."

sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
if ! compgen -G "/usr/lib/*/libLLVM.so.19*" >/dev/null && ! compgen -G "/usr/lib/*/libLLVM-19.so" >/dev/null; then
    $sudo apt-get update -qq
    $sudo apt-get install -y -qq libllvm19 >/dev/null
fi

python="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
    if ! "$python" -m venv .venv; then
        # Debian's own python3 keeps venv in a package of its own.
        rm -rf .venv
        $sudo apt-get install -y -qq python3-venv >/dev/null
        "$python" -m venv .venv
    fi
fi
.venv/bin/python -m pip install -q --disable-pip-version-check -r tools/mitsuba/requirements.txt
.venv/bin/python -c "
import sys; sys.path.insert(0, 'tools/mitsuba')
import render; render.prepare_environment()
import mitsuba as mi; mi.set_variant('llvm_ad_rgb')
print('Mitsuba', mi.__version__, 'ready in .venv (llvm variant through', render.os.environ.get('DRJIT_LIBLLVM_PATH'), ')')
"
