#!/usr/bin/env bash
# Regenerate the bundled sample (samples/walk3) from the CMU walk in ../shared/data.
# Deterministic: the same code and capture give the same images.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
data="${ZOOPRAXIS_SHARED_DATA:-$root/../shared/data}"
cd "$root"
rm -rf samples/walk3
.venv/bin/python -m zoopraxis synth --bvh "$data/cmu_mocap/131_01.bvh" --out samples/walk3 \
    --views 3 --frames 125:173 --size 480x360 --format jpg --noise 1.5 --clutter 8 \
    --marker-noise 1.5 --anchors 0,47
