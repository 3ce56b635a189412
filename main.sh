#!/usr/bin/env bash
# The main job: trains diffmpm_simple and writes its pictures and loss plot to out/diffmpm_simple/.
# On a fresh machine it first creates .venv and installs simgrad with its test (plotting) extras.
set -euo pipefail
cd "$(dirname "$0")"
if [ ! -x .venv/bin/python ] || [ pyproject.toml -nt .venv/.installed ]; then
  python3 -m venv .venv
  .venv/bin/python -m pip install --quiet -e ".[test]"
  touch .venv/.installed
fi
exec .venv/bin/python examples/diffmpm_simple.py --out out/diffmpm_simple "$@"
