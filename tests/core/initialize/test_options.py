"""The options of an initialization (core/initialize/options.py)."""

import pytest

from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.initialize.options import CAMERA_TILT_DEG, InitOptions


def test_defaults_and_what_fits_the_lengths():
    options = InitOptions()
    assert options.template == "full" and options.pose_prior == "default"
    assert options.pose_basis == "default"
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


def _what_initialize_is_given(monkeypatch, key):
    """``initialize`` replaced by one that records its keyword ``key``: the records, one view's
    plates, the command line's required arguments, and the commands ``init`` and ``track``."""
    from types import SimpleNamespace

    from zoopraxis.core.commands import init as init_command, track as track_command
    from zoopraxis.core.initialize import run

    given = []
    monkeypatch.setattr(run, "initialize", lambda *a, **kw: given.append(kw[key]) or
                        SimpleNamespace(flip_notes=list, notes=[]))
    plates = {"cam0": SimpleNamespace(image_size=(1920, 1080))}
    base = ["--markers", "markers.json", "--plate", "cam0=plate", "--out", "out.json"]
    return given, plates, base, (init_command, track_command)


def test_pose_basis_on_the_command_line(monkeypatch):
    """``init`` and ``track`` give ``initialize`` the shipped pose basis; ``--no-pose-basis``
    turns it off, and is refused with a calibration (the basis is for uncalibrated views)."""
    from zoopraxis.core.commands.common import parse_init_options
    from zoopraxis.core.initialize import run

    given, plates, base, commands = _what_initialize_is_given(monkeypatch, "pose_basis")
    for command in commands:
        for flag, expected in (([], "default"), (["--no-pose-basis"], None)):
            args = command.build_parser().parse_args(base + flag)
            options = parse_init_options(args, calibrated=False)
            run.initialize_take([], ["cam0"], plates, None, options)
            assert options.pose_basis == given[-1] == expected
        with pytest.raises(ZoopraxisError, match="--no-pose-basis is for uncalibrated views"):
            parse_init_options(command.build_parser().parse_args(base + ["--no-pose-basis"]),
                               calibrated=True)


def test_proportions_prior_on_the_command_line(monkeypatch, tmp_path):
    """``--proportions-prior FILE`` gives ``initialize`` that file's performers instead of the
    shipped prior (None); a file that is not one is refused in one line naming it."""
    import numpy as np

    from zoopraxis.core.body.body import DEFAULT_DIMS, LENGTH_DIMS
    from zoopraxis.core.commands.common import parse_init_options
    from zoopraxis.core.initialize import run
    from zoopraxis.core.priors.proportions import ProportionsPrior

    path = tmp_path / "ours.npz"
    ProportionsPrior(["a", "b"], np.array([[DEFAULT_DIMS[n] * s for n in LENGTH_DIMS]
                                           for s in (0.95, 1.05)])).save(path)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a prior")
    given, plates, base, commands = _what_initialize_is_given(monkeypatch, "proportions")
    for command in commands:
        for flag in ([], ["--proportions-prior", str(path)]):
            options = parse_init_options(command.build_parser().parse_args(base + flag), True)
            run.initialize_take([], ["cam0"], plates, {}, options)
            if flag:
                assert list(given[-1].subjects) == ["a", "b"]
            else:
                assert given[-1] is None
        with pytest.raises(ZoopraxisError, match=f"{bad}: not a proportions prior file"):
            parse_init_options(command.build_parser().parse_args(
                base + ["--proportions-prior", str(bad)]), True)
