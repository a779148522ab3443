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


@pytest.fixture
def shared_data():
    path = shared_data_dir()
    if path is None:
        pytest.skip("shared data (../shared/data) is not beside this clone")
    return path


@pytest.fixture
def rng():
    return np.random.default_rng(2345)
