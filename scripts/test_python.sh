#!/usr/bin/env bash
# test_python.sh — the Python package as a user installs it: `pip install ./python` into a
# virtual environment (build/venv; the library's CMake build kept in build/python so that a
# second run rebuilds only what changed), then its pytest tests (python/tests) against the
# Release build's `lumosaic` program (build/lumosaic), and the example script (matplotlib,
# Agg). Fails when pytest fails, collects no tests, or (in CI) skips any.
# usage: scripts/test_python.sh   (after scripts/setup.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
venv=build/venv
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
py=$PWD/$venv/bin/python
export CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-$(nproc)}
"$py" -m pip install -q --config-settings=build-dir="$PWD/build/python" ./python
"$py" -m pip install -q pytest matplotlib

export LUMOSAIC_CLI=$PWD/build/lumosaic
export LM_SHARED_DIR=${LM_SHARED_DIR:-$PWD/../shared}
export OMP_WAIT_POLICY=passive MPLBACKEND=Agg
log=$PWD/build/pytest.log
# from outside the checkout's python/, so that `import lumosaic` is the installed package
set +e
(cd build && "$py" -m pytest -p no:cacheprovider -rs -v ../python/tests) 2>&1 | tee "$log"
rc=${PIPESTATUS[0]}
set -e
if [ "$rc" -eq 5 ]; then
  echo "test_python.sh: pytest collected no tests: failing" >&2
  exit 1
fi
[ "$rc" -eq 0 ] || { echo "test_python.sh: pytest failed (status $rc)" >&2; exit "$rc"; }
if [ "${CI:-}" = "true" ] && grep -q "SKIPPED" "$log"; then
  echo "test_python.sh: Python tests were skipped in CI: failing" >&2
  exit 1
fi
