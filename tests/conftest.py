"""Shared fixtures: where the shared data lives, and a seeded random generator."""

import os
from pathlib import Path

# Small dense systems everywhere: BLAS threading only adds overhead (see __main__.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


def load_benchmark(name):
    """The module of the benchmark script ``benchmarks/NAME.py`` (not a package: loaded from
    its file)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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


_FITS = {}


@pytest.fixture
def fits_once(monkeypatch):
    """The initialization made once per set of inputs in the whole run: a call of
    ``initialize.run.initialize`` with the clicks, cameras and options of an earlier call
    (a pose prior file as its path, size and modification time) gets a copy of that call's
    result instead of fitting again. The fit is deterministic, so what a test sees is what it
    would see fitting anew; tests of the command line and the add-on that each start from the
    same one-view fit of the sample share it this way."""
    import copy
    import pickle

    from zoopraxis.core.initialize import run

    fit = run.initialize

    def once(*args, **options):
        prior = options.get("pose_prior")
        stamp = None
        if isinstance(prior, (str, os.PathLike)) and os.path.isfile(prior):
            stat = os.stat(prior)
            stamp = (stat.st_size, stat.st_mtime_ns)
        try:
            key = pickle.dumps((args, sorted(options.items()), stamp))
        except (pickle.PicklingError, TypeError, AttributeError):
            return fit(*args, **options)
        if key not in _FITS:
            _FITS[key] = fit(*args, **options)
        return copy.deepcopy(_FITS[key])

    monkeypatch.setattr(run, "initialize", once)
    return once
