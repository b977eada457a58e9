#!/usr/bin/env bash
# `make lock`: write constraints.txt from a fresh resolution of the newest releases of every
# dependency and extra the tests and benches use. Run `make test-latest` first and read
# docs/dependencies.md: the lock moves on purpose, after its checks pass.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-python3}
SCRATCH=$(mktemp -d)
trap 'rm -rf "$SCRATCH"' EXIT
"$PY" -m venv "$SCRATCH/venv"
"$SCRATCH/venv/bin/pip" install -q --upgrade pip
"$SCRATCH/venv/bin/pip" install -q -e '.[test,bench,gym,ray]'
{
  echo "# The versions the project is tested with (pip constraints: make demo, make test, .ci/run)."
  echo "# Written by 'make lock' on $("$PY" -c 'import platform; print(platform.python_version(), platform.machine())');"
  echo "# refresh and check as docs/dependencies.md says. pyproject.toml keeps the lower bounds."
  "$SCRATCH/venv/bin/pip" freeze --exclude-editable | sort -f
} > constraints.txt.tmp
mv constraints.txt.tmp constraints.txt
echo "constraints.txt: $(grep -vc '^#' constraints.txt) packages locked"
