"""The options of an initialization (core/initialize/options.py)."""

import pytest

from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.initialize.options import CAMERA_TILT_DEG, InitOptions


def test_defaults_and_what_fits_the_lengths():
    options = InitOptions()
    assert options.template == "full" and options.pose_prior == "default"
    assert options.camera_tilt == CAMERA_TILT_DEG and not options.perspective
    assert options.fits_dims
    assert not InitOptions(fit_dims=False).fits_dims
    assert not InitOptions(dims={"thigh": 0.45}).fits_dims     # given lengths are kept
    assert InitOptions(camera_tilt=(15, 5)).camera_tilt == (15.0, 5.0)
    assert InitOptions(camera_tilt=None).camera_tilt is None
    with pytest.raises(AttributeError):
        options.template = "muybridge"                          # frozen


def test_bad_options_are_refused_in_one_line():
    with pytest.raises(ZoopraxisError, match="camera tilt 95:10: the tilt must lie between"):
        InitOptions(camera_tilt=(95, 10))
    with pytest.raises(ZoopraxisError, match="depth flip at frame 3: unknown body part 'tail'"):
        InitOptions(flips={3: ["left leg", "tail"]})
    assert InitOptions(flips={3: "the Left-Leg"}).flips == {3: "the Left-Leg"}
