"""init.json: the result of an initialization written and read (core/files/initfile.py)."""

import json

import numpy as np
import pytest

from zoopraxis.core.files.initfile import init_from_json
from zoopraxis.core.initialize.run import initialize
from zoopraxis.core.synthetic import synth
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.files.markers import Anchor

from tests.core.initialize.test_initialize import clicks, ring


def test_init_json_round_trip(rng):
    body = synth.random_subject(rng)
    cams = ring(2, rng)
    X = body.joints(synth.everyday_pose(body, rng))
    result = initialize([Anchor(4, clicks(cams, X, rng))], {c.name: c for c in cams})
    data = json.loads(json.dumps(result.to_json()))
    back = init_from_json(data)
    assert np.allclose(back.joints3d(4), result.joints3d(4), atol=1e-4)
    assert back.calibrated and back.rms.keys() == result.rms.keys()
    with pytest.raises(ZoopraxisError, match="x.json: not a zoopraxis-init/1 file"):
        init_from_json({"format": "other"}, "x.json")
