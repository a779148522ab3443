"""The proportions of human bodies, learned from motion capture of many performers.

One view sees a length only through its bone's foreshortening, so a body fitted to one
view's clicks takes its proportions mostly from a prior. :class:`ProportionsPrior` holds
the lengths (``body.LENGTH_DIMS``) measured on each performer's captured joints; what the
fit uses is their mean proportions (each performer's lengths divided by his overall size)
and each length's relative spread across performers. A length the captures do not measure
keeps the template's proportion and the fixed spread ``DIMS_PRIOR_SIGMA``.

``tools/learn_proportions_prior.py`` writes the shipped file,
``core/priors/data/proportions_prior.npz``; :meth:`ProportionsPrior.load` can leave performers out
to judge the prior on them.
"""

from pathlib import Path

import numpy as np

from ..body.body import DEFAULT_DIMS, LENGTH_DIMS
from ..errors import ZoopraxisError
from ..initialize.problem import DIMS_PRIOR_SIGMA

DEFAULT_PROPORTIONS_PRIOR = Path(__file__).resolve().parent / "data" / "proportions_prior.npz"
# A length's relative spread across performers is taken as at least this: a dozen performers
# measure it no better.
MIN_SIGMA = 0.02


class ProportionsPrior:
    """Lengths of several performers, and their proportions' mean and spread.

    Parameters
    ----------
    subjects : sequence of str, length S
    lengths : array, shape (S, len(LENGTH_DIMS))
        Metres, NaN where a length was not measured.
    """

    def __init__(self, subjects, lengths):
        self.subjects = np.array([str(s) for s in subjects])
        self.lengths = np.asarray(lengths, float).reshape(len(self.subjects), len(LENGTH_DIMS))
        if not len(self.subjects):
            raise ZoopraxisError("no performers to learn proportions from")

    @classmethod
    def from_joints(cls, takes):
        """Measure each performer's lengths on his captured joints.

        Parameters
        ----------
        takes : dict of str to array, shape (F, 17, 3)
            World metres per performer (all his frames together).
        """
        from ..body.fit3d import dims_from_joints

        subjects, rows = [], []
        for subject, joints in takes.items():
            dims = dims_from_joints(joints)
            subjects.append(subject)
            rows.append([dims.get(n, np.nan) for n in LENGTH_DIMS])
        return cls(subjects, np.array(rows))

    @classmethod
    def load(cls, path=None, exclude=()):
        """Read a prior file (the shipped one by default), leaving the performers ``exclude``
        out.

        Raises
        ------
        ZoopraxisError
            Missing or malformed, or nobody left.
        """
        path = Path(path) if path is not None else DEFAULT_PROPORTIONS_PRIOR
        try:
            with np.load(path) as data:
                subjects = data["subjects"].astype(str)
                names = [str(n) for n in data["dim_names"]]
                lengths = np.asarray(data["lengths"], float)
        except (OSError, KeyError, ValueError) as exc:
            raise ZoopraxisError(f"{path}: not a proportions prior file ({exc})") from None
        if lengths.shape != (len(subjects), len(names)):
            raise ZoopraxisError(f"{path}: not a proportions prior file (lengths of shape "
                                 f"{lengths.shape} for {len(subjects)} performers)")
        table = np.full((len(subjects), len(LENGTH_DIMS)), np.nan)
        for k, name in enumerate(LENGTH_DIMS):
            if name in names:
                table[:, k] = lengths[:, names.index(name)]
        keep = ~np.isin(subjects, [str(s) for s in exclude])
        if not keep.any():
            raise ZoopraxisError(f"{path}: no performers left after leaving out "
                                 f"{', '.join(map(str, exclude))}")
        return cls(subjects[keep], table[keep])

    def save(self, path):
        """Write the performers' lengths to ``path`` (``.npz``), as :meth:`load` reads them."""
        try:
            with open(path, "wb") as stream:
                np.savez_compressed(stream, subjects=self.subjects,
                                    dim_names=np.array(LENGTH_DIMS),
                                    lengths=self.lengths.astype(np.float32))
        except OSError as error:
            raise ZoopraxisError(f"{path}: cannot write ({error.strerror})") from None

    def mean_sigma(self):
        """The prior of a body's lengths, as the fit uses it.

        Each performer's proportions are his lengths divided by his size (the median of his
        measured lengths over the template's); their mean, brought to the template's size,
        is the prior's mean, and their relative spread (at least MIN_SIGMA) its sigma.

        Returns
        -------
        mean : array, shape (len(LENGTH_DIMS),)
            Metres, of a body of the template's size.
        sigma : array, shape (len(LENGTH_DIMS),)
            Relative spread of each length about ``size * mean``.
        """
        template = np.array([DEFAULT_DIMS[n] for n in LENGTH_DIMS])
        ratio = self.lengths / template
        size = np.nanmedian(ratio, axis=1, keepdims=True)
        proportions = ratio / size                                     # (S, D), 1 = template's
        measured = np.isfinite(proportions).sum(axis=0)
        mean = np.nansum(proportions, axis=0) / np.maximum(measured, 1)
        mean[measured == 0] = 1.0
        spread = np.full(len(LENGTH_DIMS), DIMS_PRIOR_SIGMA)
        several = measured > 1
        if several.any():
            spread[several] = np.nanstd(proportions[:, several] / mean[several], axis=0, ddof=1)
        sigma = np.where(several, np.maximum(spread, MIN_SIGMA), DIMS_PRIOR_SIGMA)
        mean = mean / np.median(mean[measured > 0]) if (measured > 0).any() else mean
        return template * mean, sigma


_DEFAULT = {}


def default_proportions_prior():
    """The shipped prior, or None without its file."""
    if "prior" not in _DEFAULT:
        _DEFAULT["prior"] = ProportionsPrior.load() if DEFAULT_PROPORTIONS_PRIOR.is_file() \
            else None
    return _DEFAULT["prior"]
