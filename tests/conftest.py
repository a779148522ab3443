"""Shared fixtures: where the shared data lives, and a seeded random generator."""

import os
from pathlib import Path

# Small dense systems everywhere: BLAS threading only adds overhead (see __main__.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


def shared_data_dir():
    """The workplace's shared data folder (``../shared/data`` beside the clone), or None."""
    env = os.environ.get("ZOOPRAXIS_SHARED_DATA")
    path = Path(env) if env else REPO.parent / "shared" / "data"
    return path if path.is_dir() else None


def slow_walk_take(n):
    """``n`` frames of a slow synthetic walk (CMU 131_02 from frame 200) in 2 calibrated
    320x240 views, and its true joints; skips the test without the shared data."""
    from zoopraxis.core.synthetic import synth

    data = shared_data_dir()
    if data is None:
        pytest.skip("shared data (../shared/data) is not beside this clone")
    return synth.take_from_bvh(data / "cmu_mocap" / "131_02.bvh", frames=slice(200, 200 + n),
                               views=2, image_size=(320, 240), noise=1.0, clutter=4)


@pytest.fixture
def shared_data():
    path = shared_data_dir()
    if path is None:
        pytest.skip("shared data (../shared/data) is not beside this clone")
    return path


@pytest.fixture
def rng():
    return np.random.default_rng(2345)
