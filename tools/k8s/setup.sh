#!/usr/bin/env bash
# Installs the schema check of the Kubernetes manifests (tests/kubernetes.rs) into the
# repository's Python virtualenv .venv/ (git-ignored; tools/mitsuba/setup.sh uses it too):
#
#   tools/k8s/setup.sh
#
# kubernetes-validate (requirements.txt) carries the JSON schemas of the Kubernetes releases,
# so the check runs offline; `kubectl --dry-run=client` would need a cluster to fetch them.
set -euo pipefail
cd "$(dirname "$0")/../.."

sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
python="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
    if ! "$python" -m venv .venv; then
        rm -rf .venv
        $sudo apt-get install -y -qq python3-venv >/dev/null
        "$python" -m venv .venv
    fi
fi
.venv/bin/python -m pip install -q --disable-pip-version-check -r tools/k8s/requirements.txt
.venv/bin/kubernetes-validate --strict --quiet tools/k8s/*.yaml
echo "kubernetes-validate $(.venv/bin/kubernetes-validate --version) ready in .venv; tools/k8s/*.yaml pass"
