#!/usr/bin/env bash
# Set up the environment if needed, then run the test suite; arguments go to pytest. The
# test files are shared out over one process per core (pytest-xdist; each file stays in one
# process, so its module fixtures are made once); "-n 0" runs them all in this one.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/tools/setup.sh"
cd "$root"
exec .venv/bin/python -m pytest -q -n auto --dist loadfile "$@"
