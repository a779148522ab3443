#!/usr/bin/env bash
# Create or refresh the project's environment in .venv at the repository root.
#
# Idempotent: the install runs only when requirements.txt or pyproject.toml changed since
# the last successful run (their sha256 is kept in .venv). Set PYTHON to choose the
# interpreter; bpy 5.0.1 exists for Python 3.11 only.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
stamp="$venv/.zoopraxis-setup.sha256"
python="${PYTHON:-python3}"

python_version() {
    "$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])'
}

if [ ! -x "$venv/bin/python" ]; then
    if ! command -v "$python" >/dev/null 2>&1; then
        echo "setup.sh: '$python' not found; install Python 3.11 (Debian: apt-get install python3 python3-venv)" >&2
        exit 1
    fi
    version="$(python_version "$python")"
    if [ "$version" != "3.11" ]; then
        echo "setup.sh: Python 3.11 is needed (bpy 5.0.1 is built for it) but '$python' is $version; set PYTHON=/path/to/python3.11" >&2
        exit 1
    fi
    echo "setup.sh: creating $venv"
    if ! "$python" -m venv "$venv"; then
        # A half-made venv would pass the check above next time and then lack pip.
        rm -rf "$venv"
        echo "setup.sh: '$python -m venv' failed (Debian: apt-get install python3-venv)" >&2
        exit 1
    fi
fi

version="$(python_version "$venv/bin/python")"
if [ "$version" != "3.11" ]; then
    echo "setup.sh: $venv has Python $version, not 3.11; remove it and run again" >&2
    exit 1
fi

want="$(cat "$root/requirements.txt" "$root/pyproject.toml" | sha256sum | cut -d' ' -f1)"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    exit 0
fi

echo "setup.sh: installing requirements into $venv"
pip=("$venv/bin/python" -m pip --disable-pip-version-check --quiet)
"${pip[@]}" install -r "$root/requirements.txt"
"${pip[@]}" install -e "$root" --no-deps
echo "$want" > "$stamp"
echo "setup.sh: done"
