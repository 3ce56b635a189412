#!/usr/bin/env bash
# Runs the checks and the test suite: ruff, mypy, then pytest (arguments go to pytest). On a fresh machine it
# first creates .venv and installs simgrad with its test extras (which include ruff and mypy).
set -euo pipefail
cd "$(dirname "$0")"
if [ ! -x .venv/bin/python ] || [ pyproject.toml -nt .venv/.installed ]; then
  python3 -m venv .venv
  .venv/bin/python -m pip install --quiet -e ".[test]"
  touch .venv/.installed
fi
.venv/bin/python -m ruff check simgrad tests
.venv/bin/python -m mypy simgrad
exec .venv/bin/python -m pytest -q -n 2 "$@"
