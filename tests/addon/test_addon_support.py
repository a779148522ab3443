"""Shared fixtures and helpers of the add-on tests (imported by the other test_addon_* modules).

The bpy module is one Blender session per process: the extension is registered once per test
module and the scene is reset to an empty factory state before every test.
"""

import json
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "samples" / "walk3"


@pytest.fixture(scope="module")
def registered():
    import zoopraxis
    from zoopraxis.addon import registration

    if registration.is_registered():
        registration.unregister()
    zoopraxis.register()
    yield
    zoopraxis.unregister()


@pytest.fixture
def blender(registered):
    """An empty factory scene with the extension registered; back in Object mode afterwards."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy.context
    if bpy.context.object is not None and bpy.context.object.mode != 'OBJECT':
        bpy.ops.object.mode_set(mode='OBJECT')


def synthetic_result(n_frames=20, template="full", *, seed=2345, angles=True, views=("cam0",)):
    """A TrackResult from a body moved through known angles: walking-like swings plus noise.

    Returns
    -------
    result : TrackResult
    body : BodyModel
    """
    from zoopraxis.core.body import body as body_mod
    from zoopraxis.core.geometry import se3
    from zoopraxis.core.files.result import TrackResult

    body = body_mod.make_body(template)
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / 30.0
    A = np.zeros((n_frames, body.n_dofs))
    phase = rng.uniform(0, 2 * np.pi, body.n_dofs)
    amp = 0.5 * (body.upper - body.lower) * rng.uniform(0.2, 0.5, body.n_dofs)
    mid = 0.5 * (body.upper + body.lower)
    A[:] = mid + amp * np.sin(2 * np.pi * 1.1 * t[:, None] + phase)
    roots = np.tile(np.eye(4), (n_frames, 1, 1))
    for i in range(n_frames):
        roots[i, :3, :3] = se3.exp_so3([0.1 * np.sin(t[i]), 0.05, 0.8 + 0.4 * t[i]])
        roots[i, :3, 3] = [0.3 + 0.8 * t[i], -0.2 * t[i], 0.95 + 0.02 * np.sin(6 * t[i])]
    X = body.joints(roots, A)
    uv = X[..., :2] * 100 + 200
    result = TrackResult(mode="calibrated", fps=30.0, frames=np.arange(n_frames), joints3d=X,
                         joints2d={v: uv for v in views},
                         residual={v: np.linspace(0.1, 0.5, n_frames) for v in views},
                         status=["ok"] * n_frames,
                         body={"template": template, "shapes": body.shapes, "dims": body.dims,
                               "dof_names": list(body.dof_names)},
                         roots=roots if angles else None, angles=A if angles else None)
    return result, body


def write_result(path, result):
    from zoopraxis.core.files.result import write_result as write

    write(path, result)
    return path


def read_json(path):
    return json.loads(Path(path).read_text())


def matrix_np(m):
    return np.array([list(row) for row in m], dtype=float)
