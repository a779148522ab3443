"""``python -m zoopraxis``: run the command line."""

import os
import sys

# The trackers solve many small systems; BLAS threads cost more than they give there, and on
# a loaded machine far more. Set before numpy loads (inside Blender numpy is already loaded).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from .cli import main  # noqa: E402

sys.exit(main())
