"""The realistic benchmark's repeated runs with other click noise (benchmarks/bench_realistic.py)."""

import subprocess
import sys

from conftest import load_benchmark


def test_other_click_seeds_reach_run_set(tmp_path):
    # A stand-in for ../shared/bench/run_set.py with its signature: the seed of the click
    # noise is write_inputs' last default, and main() parses the command line.
    (tmp_path / "run_set.py").write_text(
        "import argparse\n"
        "def write_inputs(gt, d, out, noise_px, frame0, uncalibrated, seed=7):\n"
        "    return seed\n"
        "def main():\n"
        "    ap = argparse.ArgumentParser(); ap.add_argument('--set')\n"
        "    a = ap.parse_args()\n"
        "    print(a.set, write_inputs(None, None, None, 2.0, 0, False))\n"
        "    return 0\n")
    bench = load_benchmark("bench_realistic")
    out = subprocess.run([sys.executable, "-c", bench.WITH_SEED, str(tmp_path), "11",
                          "--set", "walk"], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["walk", "11"]


def test_spread_line_gives_mean_and_range():
    bench = load_benchmark("bench_realistic")
    runs = [{"mpjpe": m, "pa": m - 5, "lost": lost, "knee": 6.0, "elbow": 20.0, "fps": 3.0}
            for m, lost in ((30.0, 0), (50.0, 4), (40.0, 2))]
    line = bench.spread_line("punch02", "default", runs)
    assert "mpjpe 40.0 (30.0-50.0)" in line
    assert "lost 2 (0-4)" in line
    assert line.startswith("punch02")


def test_each_set_is_tracked_with_a_prior_that_has_not_seen_its_performer(tmp_path):
    """The proportions prior given to a set's tracks leaves out the performer of the CMU take
    the set's about.json names; a set that does not say, or whose performer the prior does not
    have, gets none (the shipped prior is fair to it as it is)."""
    import json

    from zoopraxis.core.priors.proportions import ProportionsPrior

    bench = load_benchmark("bench_realistic")
    shipped = set(ProportionsPrior.load().subjects)
    assert "131" in shipped
    walk, salsa, unnamed = (tmp_path / n for n in ("walk", "salsa", "unnamed"))
    for folder, clip in ((walk, "131_01.bvh"), (salsa, "60_05.bvh"), (unnamed, None)):
        folder.mkdir()
        if clip:
            (folder / "about.json").write_text(json.dumps({"clip": clip}))
    path = bench.held_out_proportions(walk, tmp_path)
    assert set(ProportionsPrior.load(path).subjects) == shipped - {"131"}
    assert bench.performer(walk) == "131"
    assert bench.held_out_proportions(salsa, tmp_path) is None      # 60: not in the prior
    assert bench.held_out_proportions(unnamed, tmp_path) is None
