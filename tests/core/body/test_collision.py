"""Limbs kept apart: sphere proxies, penetration, and its Jacobian."""

import numpy as np
import pytest

from zoopraxis.core.body import body as bm
from zoopraxis.core.body import collision
from zoopraxis.core.geometry import se3


@pytest.mark.parametrize("template", bm.TEMPLATES)
def test_rest_pose_does_not_penetrate(template):
    body = bm.make_body(template)
    proxies = collision.body_proxies(body)
    assert len(proxies.pairs) > 50
    assert collision.penetration(proxies, body.seg2world(body.rest_pose())).max() == 0.0


def test_arm_through_the_chest_penetrates():
    body = bm.make_body("full")
    pose = body.rest_pose()
    pose.angles[body.dof_index("l_shoulder_abd")] = np.radians(-30)   # adduct into the body
    pose.angles[body.dof_index("l_shoulder_flex")] = np.radians(10)
    proxies = collision.body_proxies(body)
    assert collision.penetration(proxies, body.seg2world(pose)).max() > 0.02
    # crossing the legs through each other too
    pose = body.rest_pose()
    pose.angles[body.dof_index("l_hip_abd")] = np.radians(-25)
    assert collision.penetration(proxies, body.seg2world(pose)).max() > 0.02


def test_forearms_through_each_other_penetrate():
    """The arms are kept apart as the legs are: a hand drawn into the other arm (bare arms have
    the hands' colour) is a pose no one takes. Forearms crossed in front of the body one
    above the other do not touch."""
    body = bm.make_body("full")
    proxies = collision.body_proxies(body)
    owner = [body.segment_names[k] for k in proxies.segment]

    def overlaps(l_flex, r_flex):
        pose = body.rest_pose()
        for side, flex in (("l", l_flex), ("r", r_flex)):
            pose.angles[body.dof_index(f"{side}_shoulder_flex")] = flex
            pose.angles[body.dof_index(f"{side}_elbow_flex")] = 1.4
            pose.angles[body.dof_index(f"{side}_shoulder_rot")] = 1.0
        pen = collision.penetration(proxies, body.seg2world(pose))
        return pen.max(), {(owner[i], owner[j]) for i, j in proxies.pairs[pen > 0]}

    depth, pairs = overlaps(1.4, 1.4)
    assert depth > 0.04 and pairs == {("l_forearm", "r_forearm")}
    assert overlaps(1.4, 0.9)[0] == 0.0


def test_penalty_jacobian_against_finite_differences(rng):
    body = bm.make_body("full")
    pose = body.rest_pose(se3.transform(p=[0, 0, 1.0]))
    pose.angles[body.dof_index("l_shoulder_abd")] = np.radians(-30)
    pose.angles[body.dof_index("l_hip_abd")] = np.radians(-20)
    proxies = collision.body_proxies(body)
    T, Jseg = body.kinematics(pose)
    r, J = collision.penalty_system(proxies, T, Jseg)
    assert len(r) > 0
    h = 1e-6
    for k in (6 + body.dof_index("l_shoulder_abd"), 6 + body.dof_index("l_hip_abd"), 0, 4):
        d = np.zeros(body.n_params)
        d[k] = h
        rp = collision.penetration(proxies, body.seg2world(pose.retract(d)))
        rm = collision.penetration(proxies, body.seg2world(pose.retract(-d)))
        full = (rp - rm) / (2 * h)
        active = collision.penetration(proxies, T) > 0
        assert np.allclose(full[active], J[:, k], atol=1e-5)


@pytest.mark.parametrize("abduction", [-25, -20])
def test_gauss_newton_on_the_penalty_separates_the_limbs(abduction):
    """Damped Gauss-Newton steps on the penalty alone take an arm out of the trunk; a joint at
    its limit that a step would push further is held. (Undamped minimum-norm steps, which
    this test once took from the arm at its very limit, -30 degrees, jumped by 1e13 radians
    where the system was singular and separated the limbs or not by the last bit.)"""
    body = bm.make_body("full")
    pose = body.rest_pose()
    pose.angles[body.dof_index("l_shoulder_abd")] = np.radians(abduction)
    proxies = collision.body_proxies(body)
    assert collision.penetration(proxies, body.seg2world(pose)).max() > 0.01
    for _ in range(20):
        T, Jseg = body.kinematics(pose)
        r, J = collision.penalty_system(proxies, T, Jseg)
        if not len(r):
            break
        J = J[:, 6:]
        free = np.ones(body.n_dofs, bool)
        for _ in range(3):
            delta = np.zeros(body.n_dofs)
            Jf = J[:, free]
            delta[free] = -np.linalg.solve(Jf.T @ Jf + 1e-3 * np.eye(free.sum()), Jf.T @ r)
            beyond = (pose.angles + delta < body.lower) | (pose.angles + delta > body.upper)
            if not beyond.any():
                break
            free &= ~beyond
        pose.angles = body.clamp(pose.angles + delta)
    assert collision.penetration(proxies, body.seg2world(pose)).max() < 1e-3
