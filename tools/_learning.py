"""What the scripts that learn a prior from the CMU captures share: where the captures are, and
the options every one of them takes."""

import argparse
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = [REPO.parent / "shared" / "data" / "cmu_more", REPO.parent / "shared" / "data" / "cmu_mocap"]


def learning_parser(doc, default_out):
    """An argument parser with ``--data`` (folders of captures), ``--hold-out`` (CMU subjects
    left out), ``--out`` (default ``default_out``) and ``--force``; the description is the
    first paragraph of ``doc``."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--data", type=Path, nargs="+", default=DATA)
    parser.add_argument("--hold-out", nargs="*", default=[], metavar="SUBJECT",
                        help="CMU subjects to leave out (02, 35, ...)")
    parser.add_argument("--out", type=Path, default=default_out)
    parser.add_argument("--force", action="store_true", help="replace an existing output")
    return parser
