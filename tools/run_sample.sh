#!/usr/bin/env bash
# Set up the environment if needed, then run the main job on the bundled sample (out/sample).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/tools/setup.sh"
cd "$root"
exec .venv/bin/python -m zoopraxis demo "$@"
