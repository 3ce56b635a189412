#!/usr/bin/env bash
# Runs the test suite; on a fresh machine it first creates .venv and installs simgrad with its test extras.
set -euo pipefail
cd "$(dirname "$0")"
if [ ! -x .venv/bin/python ] || [ pyproject.toml -nt .venv/.installed ]; then
  python3 -m venv .venv
  .venv/bin/python -m pip install --quiet -e ".[test]"
  touch .venv/.installed
fi
exec .venv/bin/python -m pytest -q -n 2 "$@"
