"""The synthetic tracking benchmark's options reach ``track`` (benchmarks/bench_track.py)."""

import inspect

from conftest import load_benchmark


def test_case_options_are_track_arguments():
    # walk1-near once passed perspective=True, which track() no longer takes (the perspective
    # is an initialization option now): the case failed with a TypeError after rendering.
    bench = load_benchmark("bench_track")
    from zoopraxis.core.take import track as T

    params = inspect.signature(T.track).parameters
    for case, options in bench.CASE_OPTIONS.items():
        assert case in bench.CASES
        assert set(options) <= set(params), (case, set(options) - set(params))
    assert bench.CASE_OPTIONS["walk1-near"]["init_options"].perspective
