#!/usr/bin/env bash
# `make test-latest`: the newest releases of every dependency in a scratch environment
# (.venv-latest, no lock), the whole test suite there, then the reference drives' CSV bytes
# against the locked environment (.venv). Exit status: non-zero when a test fails or a drive's
# bytes moved. docs/dependencies.md says what to do with the result.
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-python3}
LATEST=.venv-latest
rm -rf "$LATEST" out/drift
"$PY" -m venv "$LATEST"
"$LATEST/bin/pip" install -q --upgrade pip
"$LATEST/bin/pip" install -q --upgrade -e '.[test]' || exit 1
echo "== the test suite with the newest releases"
"$LATEST/bin/python" -m pytest -n 2
tests=$?
echo "== the reference drives: locked (.venv) against newest ($LATEST)"
.venv/bin/python tools/reference_drives.py out/drift/locked || exit 1
"$LATEST/bin/python" tools/reference_drives.py out/drift/latest || exit 1
.venv/bin/python tools/reference_drives.py --compare out/drift/locked out/drift/latest
drives=$?
echo "== releases newer than the lock (constraints.txt)"
"$LATEST/bin/pip" freeze --exclude-editable | "$LATEST/bin/python" -c '
import sys
def pins(lines):
    out = {}
    for line in lines:
        if "==" in line and not line.startswith("#"):
            name, version = line.strip().split("==", 1)
            out[name.lower().replace("_", "-")] = version
    return out
locked, newest = pins(open("constraints.txt")), pins(sys.stdin)
moved = [f"  {n}: {locked[n]} -> {v}" for n, v in sorted(newest.items()) if n in locked and locked[n] != v]
new = [f"  {n}: {v} (not in the lock)" for n, v in sorted(newest.items()) if n not in locked]
print("\n".join(moved + new) or "  none: the lock is the newest")
'
if [ "$tests" -ne 0 ] || [ "$drives" -ne 0 ]; then
  echo "test-latest: tests exit $tests, drives exit $drives: the newest releases change results"
  exit 1
fi
echo "test-latest: the newest releases pass every test and give the locked drives' bytes"
