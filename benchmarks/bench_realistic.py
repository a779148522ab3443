"""Realistic benchmark sets: every set with every tracker, one table.

The sets are Cycles renders of CMU performers (skinned, clothed body, shadows, glossy floors,
clutter, sensor noise) in ``../shared/bench/sets`` (or ``$ZOOPRAXIS_BENCH``), with ground truth.
Each run goes through ``../shared/bench/run_set.py``, which runs ``python -m zoopraxis track``
as a user would (clicks: the true 2D joints of frame 0 plus 2 px of noise) and scores it.

    .venv/bin/python benchmarks/bench_realistic.py [--sets a,b] [--trackers default,hybrid]
        [--keep DIR] [--extra-sets DIR] [--click-seeds 7,8,9]
        [--track-args "--motion-prior general"] [--shipped-priors]

Columns: MPJPE and Procrustes-aligned PA-MPJPE (mm), frames lost (the tracker said "lost" or
MPJPE over 150 mm; for one view, PA-MPJPE over 150 mm), knee and elbow flexion RMSE (degrees),
frames per second (wall time with start-up), and how the per-frame status agrees with the
error: frames over 150 mm called ok (must be 0), frames called lost that are under 150 mm,
frames called lost with no joint over 150 mm (false alarms: nothing to fix), frames called ok
that are under 50 mm, over all frames called ok.
``--extra-sets DIR`` adds every set folder under DIR (sets rendered with
``../shared/bench/render``; they stay outside the repository). ``--track-args`` adds options to
every ``zoopraxis track`` that run_set.py runs (it has no option for that): run_set.py then
runs from a scratch folder whose ``.venv/bin/python`` is a script that adds them (POSIX only).

The lengths' prior learned from captured performers (``core/priors/data/proportions_prior.npz``)
was learned from the very performers the sets show. Each set's track is therefore given that
prior without the set's performer (the subject of the CMU take its ``about.json`` names), through
``zoopraxis track --proportions-prior`` (as ``--track-args``): the numbers are those of
performers the priors have not seen. ``--shipped-priors`` tracks with the shipped file as is.

``--click-seeds`` runs each set and tracker once per seed of the clicks' 2 px noise (run_set.py
draws it with seed 7) and adds a line with the mean and the range over the seeds. A tracker that
loses a limb can lose it or not from one set of clicks to the next; a change smaller than that
range on one set is not a change.
"""

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TRACKERS = ["default", "hybrid", "particle"]
LINE = re.compile(r"MPJPE ([\d.]+) mm, PA ([\d.]+) mm, lost (\d+)/(\d+) \(after alignment (\d+)\), "
                  r"knee ([\d.]+) deg, elbow ([\d.]+) deg, ([\d.]+) frames/s")


def bench_dir():
    return Path(os.environ.get("ZOOPRAXIS_BENCH", ROOT.parent / "shared" / "bench"))


def status_agreement(set_dir, result_path, single_view):
    """Frames over 150 mm called ok, frames called lost under 150 mm, and the share of frames
    called ok that are under 50 mm (per-frame MPJPE; PA-MPJPE for one view)."""
    sys.path.insert(0, str(bench_dir()))
    from run_set import STD, load_gt, procrustes

    gt = load_gt(set_dir)
    r = json.loads(Path(result_path).read_text())
    idx = [r["joints"].index(j) for j in STD]
    pred = np.asarray(r["joints3d"], float)[:, idx]
    truth = gt["j3"][np.asarray(r["frames"], int)]
    if single_view:
        joint = np.array([np.linalg.norm(procrustes(p, g) - g, axis=-1)
                          for p, g in zip(pred, truth)]) * 1000
    else:
        joint = np.linalg.norm(pred - truth, axis=-1) * 1000
    err, worst = joint.mean(1), joint.max(1)
    status = np.array(r["status"])
    ok, lost = status == "ok", status == "lost"
    return {"ok_over_150": int(np.sum(ok & (err > 150))),
            "lost_under_150": int(np.sum(lost & (err <= 150))),
            "lost_nothing": int(np.sum(lost & (worst <= 150))),
            "ok_good": f"{int(np.sum(ok & (err < 50)))}/{int(ok.sum())}",
            "statuses": f"{int(ok.sum())}/{int(np.sum(status == 'uncertain'))}/{int(lost.sum())}"}


# run_set.py's seed of the click noise.
RUN_SET_SEED = 7

# run_set.py with another seed of the click noise (its one scorer, unchanged otherwise):
# python -c WITH_SEED BENCH_DIR SEED [run_set arguments]
WITH_SEED = ("import sys; sys.path.insert(0, sys.argv.pop(1)); seed = int(sys.argv.pop(1)); "
             "import run_set; run_set.write_inputs.__defaults__ = (seed,); "
             "sys.exit(run_set.main())")


def checkout_with_track_args(track_args):
    """A scratch folder whose ``.venv/bin/python`` is this checkout's, with ``track_args``
    added to ``-m zoopraxis track`` (run_set.py runs ``.venv/bin/python`` of its folder)."""
    folder = Path(tempfile.mkdtemp(prefix="zp-track-args-"))
    script = folder / ".venv" / "bin" / "python"
    script.parent.mkdir(parents=True)
    python = shlex.quote(str(ROOT / ".venv" / "bin" / "python"))
    script.write_text("#!/bin/sh\n"
                      f'if [ "$1 $2 $3" = "-m zoopraxis track" ]; then exec {python} "$@" '
                      f"{' '.join(map(shlex.quote, shlex.split(track_args)))}; fi\n"
                      f'exec {python} "$@"\n')
    script.chmod(0o755)
    return folder


def run(set_dir, tracker, keep, seed=RUN_SET_SEED, cwd=ROOT):
    keep = Path(keep) / (f"{set_dir.name}_{tracker}" if seed == RUN_SET_SEED
                         else f"{set_dir.name}_{tracker}_clicks{seed}")
    python = str(ROOT / ".venv" / "bin" / "python")
    cmd = [python, str(bench_dir() / "run_set.py")] if seed == RUN_SET_SEED else \
        [python, "-c", WITH_SEED, str(bench_dir()), str(seed)]
    cmd += ["--set", str(set_dir), "--keep", str(keep)]
    if tracker != "default":
        cmd += ["--tracker", tracker]
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd)
    m = LINE.search(p.stdout)
    if not m:
        tail = (p.stdout + p.stderr).strip().splitlines()[-1:]
        return {"error": " ".join(tail)[:120]}
    mp, pa, lost, n, pa_lost, knee, elbow, fps = m.groups()
    views = len([d for d in set_dir.iterdir() if d.is_dir() and d.name.startswith("cam")])
    out = {"views": views, "mpjpe": float(mp), "pa": float(pa), "lost": int(lost),
           "pa_lost": int(pa_lost), "frames": int(n), "knee": float(knee),
           "elbow": float(elbow), "fps": float(fps)}
    out.update(status_agreement(set_dir, keep / "result.json", views == 1))
    return out


def performer(set_dir):
    """The CMU subject a rendered set shows (its ``about.json`` names the take, e.g.
    ``131_01.bvh``), or None."""
    try:
        clip = json.loads((set_dir / "about.json").read_text())["clip"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return Path(clip).stem.split("_")[0]


def held_out_proportions(set_dir, folder):
    """A proportions prior file in ``folder``: the shipped one without ``set_dir``'s performer,
    or None when the shipped one does not have him (or the set does not say who he is)."""
    from zoopraxis.core.priors.proportions import ProportionsPrior

    subject = performer(set_dir)
    shipped = ProportionsPrior.load()
    if subject is None or subject not in set(shipped.subjects):
        return None
    path = Path(folder) / f"proportions_without_{subject}.npz"
    ProportionsPrior.load(exclude=[subject]).save(path)
    return path


def spread_line(name, tracker, runs):
    """Mean and range over click seeds of MPJPE, PA-MPJPE, lost frames and joint angles."""
    def stat(key, fmt):
        x = np.array([r[key] for r in runs], float)
        return f"{key} {x.mean():{fmt}} ({x.min():{fmt}}-{x.max():{fmt}})"

    return (f"{name:16} {tracker:9} {'mean':>6}  " + ", ".join(
        stat(k, f) for k, f in (("mpjpe", ".1f"), ("pa", ".1f"), ("lost", ".0f"),
                                ("knee", ".1f"), ("elbow", ".1f"), ("fps", ".2f"))))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", help="comma-separated set names (default: all)")
    ap.add_argument("--trackers", default=",".join(TRACKERS))
    ap.add_argument("--extra-sets", help="a folder of more sets (each with gt.npz)")
    ap.add_argument("--keep", help="keep each run's inputs and result.json here")
    ap.add_argument("--click-seeds", default=str(RUN_SET_SEED),
                    help="comma-separated seeds of the clicks' noise (default: run_set.py's)")
    ap.add_argument("--track-args", default="",
                    help="options added to every track, e.g. \"--motion-prior general\"")
    ap.add_argument("--shipped-priors", action="store_true",
                    help="track with the shipped proportions prior, the sets' performers in it")
    a = ap.parse_args()
    try:
        seeds = [int(x) for x in a.click_seeds.split(",")]
    except ValueError:
        print(f"--click-seeds: expected whole numbers separated by commas, got {a.click_seeds!r}")
        return 2
    roots = [bench_dir() / "sets"] + ([Path(a.extra_sets)] if a.extra_sets else [])
    sets = sorted((d for r in roots if r.is_dir() for d in r.iterdir()
                   if (d / "gt.npz").exists()), key=lambda d: d.name)
    if a.sets:
        wanted = a.sets.split(",")
        sets = [d for d in sets if d.name in wanted]
    if not sets:
        print(f"no sets found under {', '.join(map(str, roots))}")
        return 2
    keep = a.keep or tempfile.mkdtemp(prefix="zp-realistic-")
    head = (f"{'set':16} {'tracker':9} {'clicks':>6} {'views':>5} {'MPJPE':>6} {'PA':>6} "
            f"{'lost':>5} {'PAlost':>6} {'knee':>5} {'elbow':>5} {'fps':>5}  {'ok/unc/lost':>11} "
            f"{'ok>150':>6} {'lost<150':>8} {'lost-fine':>9} {'ok<50':>7}")
    print(head)
    print("-" * len(head))
    priors = tempfile.mkdtemp(prefix="zp-held-out-")
    for d in sets:
        held_out = None if a.shipped_priors else held_out_proportions(d, priors)
        track_args = a.track_args + (f" --proportions-prior {shlex.quote(str(held_out))}"
                                     if held_out else "")
        cwd = checkout_with_track_args(track_args) if track_args else ROOT
        for tracker in a.trackers.split(","):
            runs = []
            for seed in seeds:
                r = run(d, tracker, keep, seed, cwd)
                if "error" in r:
                    print(f"{d.name:16} {tracker:9} {seed:6d} failed: {r['error']}")
                    continue
                runs.append(r)
                print(f"{d.name:16} {tracker:9} {seed:6d} {r['views']:5d} {r['mpjpe']:6.1f} "
                      f"{r['pa']:6.1f} {r['lost']:5d} {r['pa_lost']:6d} {r['knee']:5.1f} "
                      f"{r['elbow']:5.1f} {r['fps']:5.2f}  {r['statuses']:>11} "
                      f"{r['ok_over_150']:6d} {r['lost_under_150']:8d} {r['lost_nothing']:9d} "
                      f"{r['ok_good']:>7}", flush=True)
            if len(runs) > 1:
                print(spread_line(d.name, tracker, runs), flush=True)
    print(f"(runs kept in {keep}; lost: said lost or MPJPE > 150 mm, PA-MPJPE for one view; "
          "PAlost: PA-MPJPE > 150 mm; ok>150, lost<150: frames called ok over 150 mm and called "
          "lost under it; lost-fine: called lost with no joint over 150 mm; ok<50: frames "
          "called ok under 50 mm / frames called ok)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
