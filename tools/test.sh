#!/usr/bin/env bash
# Set up the environment if needed, then run the test suite; arguments go to pytest.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/tools/setup.sh"
cd "$root"
exec .venv/bin/python -m pytest -q "$@"
