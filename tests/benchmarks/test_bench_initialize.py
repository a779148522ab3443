"""The one-view oracle of the initialization benchmark (benchmarks/bench_initialize.py): a fit
whose only fault is a limb's depth sign counts as right, any other fault does not."""

import numpy as np

from conftest import load_benchmark


def test_right_signs_error_forgives_a_limb_turned_to_its_other_depth_only():
    bench = load_benchmark("bench_initialize")
    from zoopraxis.core.body.joints import JOINT_INDEX
    from zoopraxis.core.body.kinematics import kinematics

    kin = kinematics("full")
    X = kin.forward(kin.start_angles()[None], kin.default_dims)[0][0]
    camera = bench.ring(1, np.random.default_rng(3), bench.FHD_100M, bench.aim_at(X))[0]
    depth = camera.R[2]
    X[JOINT_INDEX["l_wrist"]] += 0.15 * depth             # the forearm towards the camera
    assert bench.right_signs_error(X, X, camera) < 1e-9
    elbow, wrist = JOINT_INDEX["l_elbow"], JOINT_INDEX["l_wrist"]
    turned = X.copy()
    turned[wrist] -= 2.0 * ((turned[wrist] - turned[elbow]) @ depth) * depth
    assert 1000 * bench.procrustes_mpjpe(turned, X) > 5.0
    assert bench.right_signs_error(turned, X, camera) < 1e-6
    moved = X.copy()
    moved[wrist] += 0.1 * camera.R[0]                      # off in the image: not a sign
    assert bench.right_signs_error(moved, X, camera) > 3.0
