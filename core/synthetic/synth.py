"""Synthetic plates: textured bodies driven by motion capture, rendered into calibrated views.

The fixture that tracker tests and benchmarks use. It must not flatter the trackers, so the body
rendered here is *not* the trackers' model: its segments are capsules and tapered, rounded tubes
placed on the motion capture's own skeleton (other proportions than the body templates), with an
adjustable build, solid clothing and skin textures, Lambert shading, a textured and cluttered
background and sensor noise. Ground truth is the capture's 17 standard joints, in 3D and
projected into every view.

Convention: world Z up, metres; cameras and pixels as in :mod:`camera`. Frame ``i`` of the plates
is frame ``i`` of the (resampled) motion.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..body import primitives
from ..imaging import render
from ..geometry.camera import ring_of_cameras
from ..errors import ZoopraxisError
from ..body.joints import JOINT_INDEX, STANDARD_JOINTS

# -- the synthetic body ---------------------------------------------------------------------------

# (segment, from joint, to joint, base radius, top radius, material); radii in metres for the
# "average" build. Names are this module's own: they are not the body templates' segments.
_LIMBS = (
    ("l_upper_arm", "l_shoulder", "l_elbow", 0.052, 0.040, "sleeve"),
    ("r_upper_arm", "r_shoulder", "r_elbow", 0.052, 0.040, "sleeve"),
    ("l_forearm", "l_elbow", "l_wrist", 0.040, 0.030, "skin"),
    ("r_forearm", "r_elbow", "r_wrist", 0.040, 0.030, "skin"),
    ("l_thigh", "l_hip", "l_knee", 0.085, 0.055, "trousers"),
    ("r_thigh", "r_hip", "r_knee", 0.085, 0.055, "trousers"),
    ("l_shank", "l_knee", "l_ankle", 0.055, 0.037, "trousers"),
    ("r_shank", "r_knee", "r_ankle", 0.055, 0.037, "trousers"),
)

BUILDS = {"slim": 0.85, "average": 1.0, "heavy": 1.25}

# Materials: base colour (BGR, 0..1), texture contrast, texture scale (features per metre),
# stripe frequency along the segment (0 for none).
_MATERIALS = {
    "shirt": ((0.25, 0.35, 0.75), 0.45, 28.0, 18.0),
    "sleeve": ((0.25, 0.35, 0.75), 0.45, 28.0, 18.0),
    "trousers": ((0.45, 0.30, 0.20), 0.40, 35.0, 0.0),
    "skin": ((0.55, 0.65, 0.85), 0.18, 22.0, 0.0),
    "hair": ((0.15, 0.18, 0.22), 0.35, 45.0, 0.0),
    "shoes": ((0.12, 0.12, 0.12), 0.30, 40.0, 0.0),
}


@dataclass
class SynthBody:
    """Segments of the synthetic body and their motion.

    Attributes
    ----------
    names : list of str
    materials : list of str
    prims : primitives.Primitives
        Shapes in each segment's local frame.
    seg2world : array, shape (F, S, 4, 4)
    """

    names: list
    materials: list
    prims: primitives.Primitives
    seg2world: np.ndarray


def _bone_frames(a, b, x_ref):
    """Per-frame transforms with origin ``a``, z along ``b - a`` and x as close to ``x_ref``.

    Parameters
    ----------
    a, b, x_ref : array, shape (F, 3)

    Returns
    -------
    world_from_bone : array, shape (F, 4, 4)
    length : float
        Mean bone length over the frames.
    """
    z = b - a
    length = np.linalg.norm(z, axis=-1)
    z = z / length[:, None]
    x = x_ref - np.sum(x_ref * z, axis=-1, keepdims=True) * z
    bad = np.linalg.norm(x, axis=-1) < 1e-6
    if np.any(bad):  # x_ref along the bone: any perpendicular will do
        alt = np.cross(z[bad], [0.0, 1.0, 0.0])
        x[bad] = alt
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    T = np.zeros(a.shape[:-1] + (4, 4))
    T[..., :3, 0] = x
    T[..., :3, 1] = np.cross(z, x)
    T[..., :3, 2] = z
    T[..., :3, 3] = a
    T[..., 3, 3] = 1.0
    return T, float(length.mean())


def synth_body(joints, joint_frames, build="average"):
    """Build the synthetic body on a captured skeleton.

    Parameters
    ----------
    joints : array, shape (F, 17, 3)
        Standard joints in world metres (:func:`cmu.standard_joints`).
    joint_frames : array, shape (F, 17, 4, 4)
        World transforms of the bone starting at each joint (:func:`cmu.standard_joint_frames`);
        their rotation sets each limb's axial twist, so textures turn with the limb.
    build : {"slim", "average", "heavy"} or float
        Radius scale of the limbs and trunk.
    """
    scale = BUILDS.get(build, build) if isinstance(build, str) else float(build)
    if isinstance(scale, str):
        raise ZoopraxisError(f"unknown build '{build}' (expected {', '.join(BUILDS)} or a number)")
    J = {name: joints[:, i] for i, name in enumerate(STANDARD_JOINTS)}
    Rx = {name: joint_frames[:, i, :3, 0] for i, name in enumerate(STANDARD_JOINTS)}
    names, materials, frames, prims = [], [], [], []

    def add(name, material, T, shapes):
        k = len(names)
        names.append(name)
        materials.append(material)
        frames.append(T)
        prims.extend(shape(k) for shape in shapes)

    hips = J["l_hip"] - J["r_hip"]
    shoulders = J["l_shoulder"] - J["r_shoulder"]
    hip_w = float(np.linalg.norm(hips, axis=-1).mean())
    sh_w = float(np.linalg.norm(shoulders, axis=-1).mean())

    # Trunk: lower part follows the hips, upper part the shoulders, so the spine can bend.
    T, L = _bone_frames(J["pelvis"], J["neck"], hips)
    rx, ry = 0.62 * hip_w * scale + 0.04, 0.10 * scale
    add("hips", "trousers", T, [
        lambda k: primitives.cylinder(k, (0, 0, -0.09), (0, 0, 0.45 * L), rx, 0.92 * rx,
                                  ry_ratio=ry / rx, x_dir=(1, 0, 0)),
        lambda k: primitives.ellipsoid(k, (0, 0, -0.09), (rx, ry, 0.06))])
    T, L = _bone_frames(J["pelvis"], J["neck"], shoulders)
    T_chest = T.copy()
    T_chest[..., :3, 3] = J["neck"]  # origin at the neck; the chest hangs below it
    cx, cy = 0.5 * sh_w * scale + 0.01, 0.105 * scale
    add("chest", "shirt", T_chest, [
        lambda k: primitives.cylinder(k, (0, 0, -0.62 * L), (0, 0, -0.05), 0.92 * cx, cx,
                                  ry_ratio=cy / cx, x_dir=(1, 0, 0)),
        lambda k: primitives.ellipsoid(k, (0, 0, -0.05), (cx, cy, 0.06)),
        lambda k: primitives.ellipsoid(k, (sh_w / 2, 0, -0.05), (0.06 * scale,) * 3),
        lambda k: primitives.ellipsoid(k, (-sh_w / 2, 0, -0.05), (0.06 * scale,) * 3)])
    # Head and neck, oriented by the head bone.
    T, L = _bone_frames(J["neck"], J["head"], Rx["neck"])
    add("head", "skin", T, [
        lambda k: primitives.cylinder(k, (0, 0, -0.02), (0, 0, 0.6 * L), 0.05, 0.048),
        lambda k: primitives.ellipsoid(k, (0, 0.01, L), (0.078, 0.095, 0.115))])
    T2 = T.copy()
    add("hair", "hair", T2, [lambda k: primitives.ellipsoid(k, (0, 0.025, L + 0.035),
                                                        (0.082, 0.092, 0.09))])
    for name, a, b, r0, r1, material in _LIMBS:
        T, L = _bone_frames(J[a], J[b], Rx[a])
        r0, r1 = r0 * scale, r1 * scale

        def tube(k, L=L, r0=r0, r1=r1):
            return primitives.cylinder(k, (0, 0, 0), (0, 0, L), r0, r1)

        def cap0(k, r0=r0):
            return primitives.ellipsoid(k, (0, 0, 0), (r0,) * 3)

        def cap1(k, L=L, r1=r1):
            return primitives.ellipsoid(k, (0, 0, L), (r1,) * 3)

        add(name, material, T, [tube, cap0, cap1])
    for s in ("l", "r"):
        T, L = _bone_frames(J[f"{s}_wrist"], J[f"{s}_wrist"] + (J[f"{s}_wrist"] - J[f"{s}_elbow"]),
                            Rx[f"{s}_wrist"])
        add(f"{s}_hand", "skin", T, [lambda k: primitives.ellipsoid(k, (0, 0, 0.07),
                                                                (0.025, 0.045, 0.08))])
        # Foot: from the ankle to a little past the ball, x across the foot.
        T, L = _bone_frames(J[f"{s}_ankle"], J[f"{s}_toe"], J["l_hip"] - J["r_hip"])
        add(f"{s}_foot", "shoes", T, [
            lambda k, L=L: primitives.ellipsoid(k, (0, 0, 0.45 * L), (0.045, 0.05, 0.72 * L)),
            lambda k: primitives.ellipsoid(k, (0, 0, 0), (0.048, 0.048, 0.05))])
    return SynthBody(names, materials, primitives.Primitives.concat(prims),
                     np.stack(frames, axis=1))


# -- textures -----------------------------------------------------------------------------------

class _SolidNoise:
    """Smooth 3D value noise on a periodic random lattice, evaluated vectorized."""

    def __init__(self, rng, size=32):
        self.size = size
        self.table = rng.uniform(-1.0, 1.0, size=(size, size, size)).astype(np.float32)

    def __call__(self, p):
        n = self.size
        i0 = np.floor(p).astype(np.int64)
        f = (p - i0).astype(np.float32)
        f = f * f * (3 - 2 * f)  # smoothstep: continuous gradients across lattice cells
        i0 %= n
        i1 = (i0 + 1) % n
        t = self.table
        out = 0.0
        for dx in (0, 1):
            ix = i1[..., 0] if dx else i0[..., 0]
            wx = f[..., 0] if dx else 1 - f[..., 0]
            for dy in (0, 1):
                iy = i1[..., 1] if dy else i0[..., 1]
                wy = f[..., 1] if dy else 1 - f[..., 1]
                for dz in (0, 1):
                    iz = i1[..., 2] if dz else i0[..., 2]
                    wz = f[..., 2] if dz else 1 - f[..., 2]
                    out = out + t[ix, iy, iz] * (wx * wy * wz)
        return out


def _background(rng, width, height, clutter):
    """A static textured background: multi-scale noise, a floor gradient, optional clutter."""
    img = np.zeros((height, width, 3), np.float32)
    base = rng.uniform(0.35, 0.6, size=3).astype(np.float32)
    img[:] = base
    for cells, amp in ((4, 0.18), (16, 0.10), (60, 0.06)):
        small = rng.uniform(-1, 1, size=(cells * height // width + 2, cells + 2, 3))
        img += amp * cv2.resize(small.astype(np.float32), (width, height),
                                interpolation=cv2.INTER_CUBIC)
    ramp = np.linspace(-0.08, 0.12, height, dtype=np.float32)[:, None, None]
    img += ramp
    if clutter:
        for _ in range(int(clutter)):
            colour = rng.uniform(0.1, 0.95, size=3)
            x0, y0 = rng.integers(0, width), rng.integers(0, height)
            w, h = rng.integers(width // 20, width // 5), rng.integers(height // 20, height // 3)
            patch = colour + 0.15 * rng.uniform(-1, 1, size=(h, w, 3))
            if rng.uniform() < 0.5:
                mask = np.zeros((h, w), np.uint8)
                cv2.ellipse(mask, (w // 2, h // 2), (w // 2, h // 2), 0, 0, 360, 1, -1)
            else:
                mask = np.ones((h, w), np.uint8)
            ys, xs = slice(y0, min(y0 + h, height)), slice(x0, min(x0 + w, width))
            sub = mask[: ys.stop - y0, : xs.stop - x0].astype(bool)
            img[ys, xs][sub] = patch[: ys.stop - y0, : xs.stop - x0][sub]
    return np.clip(img, 0, 1)


@dataclass
class Scene:
    """Everything needed to render one take: body, cameras, backgrounds, textures."""

    body: SynthBody
    cameras: list
    backgrounds: list
    noise: float = 0.0
    light: np.ndarray = field(default_factory=lambda: np.array([0.3, -0.6, 0.75]))
    seed: int = 2345

    def __post_init__(self):
        rng = np.random.default_rng(self.seed)
        self._noise_fields = {m: _SolidNoise(rng) for m in _MATERIALS}
        self.light = np.asarray(self.light, float) / np.linalg.norm(self.light)
        self._noise_rng = np.random.default_rng(self.seed + 1)

    @property
    def num_frames(self):
        return self.body.seg2world.shape[0]

    def render_frame(self, frame, view):
        """Render one frame of one view.

        Returns
        -------
        image : array, shape (H, W, 3) uint8
            BGR image.
        label : array, shape (H, W) int16
            Synthetic segment per pixel (-1 background), for tests.
        """
        cam = self.cameras[view]
        seg2world = self.body.seg2world[frame]
        res = render.render(cam, seg2world, self.body.prims, want=("point", "normal"))
        img = self.backgrounds[view].copy()
        fg = res.label >= 0
        if np.any(fg):
            lab = res.label[fg].astype(np.int64)
            pts = res.point[fg].astype(np.float64)
            nrm = res.normal[fg]
            # Texture coordinates live on the segment, so the texture moves with it.
            world2seg = np.linalg.inv(seg2world)
            local = np.einsum("nij,nj->ni", world2seg[lab, :3, :3], pts) + world2seg[lab, :3, 3]
            colour = np.empty((len(lab), 3), np.float32)
            for k, material in enumerate(self.body.materials):
                sel = lab == k
                if not np.any(sel):
                    continue
                base, contrast, freq, stripes = _MATERIALS[material]
                p = local[sel] * freq + 7.3 * k
                tex = 0.65 * self._noise_fields[material](p) \
                    + 0.35 * self._noise_fields[material](2.7 * p + 3.1)
                if stripes:
                    tex = 0.5 * tex + 0.5 * np.sin(local[sel, 2] * stripes * 2 * np.pi)
                colour[sel] = np.asarray(base, np.float32) * (1.0 + contrast * tex)[:, None]
            shade = 0.35 + 0.65 * np.clip(nrm @ self.light.astype(np.float32), 0.0, 1.0)
            img[fg] = colour * shade[:, None]
        if self.noise > 0:
            img = img + self._noise_rng.normal(0.0, self.noise / 255.0,
                                               size=img.shape).astype(np.float32)
        return np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8), res.label


def _inside(uv, width, height, margin):
    m = margin * np.array([width, height])
    return bool(np.all(uv >= m) and np.all(uv <= np.array([width, height]) - 1 - m))


def make_scene(joints, joint_frames, *, views=3, image_size=(480, 360), build="average",
               noise=0.0, clutter=0, seed=2345, radius=None, camera_height=1.3, focal_px=None,
               start_angle=None):
    """Place a ring of cameras around the motion and prepare the backgrounds.

    The cameras look at the middle of the motion's path from a distance that keeps the whole
    path in view (at the given focal length), so a walk stays in frame.
    """
    joints = np.asarray(joints, float)
    if joints.ndim != 3 or joints.shape[1:] != (17, 3):
        raise ZoopraxisError(f"joints must have shape (F, 17, 3), got {joints.shape}")
    width, height = image_size
    lo, hi = joints.reshape(-1, 3).min(axis=0), joints.reshape(-1, 3).max(axis=0)
    target = (lo + hi) / 2
    target[2] = (lo[2] + hi[2]) / 2
    extent = max(np.linalg.norm((hi - lo)[:2]), 0.5)
    body_h = hi[2] - lo[2] + 0.25
    if focal_px is None:
        focal_px = 1.1 * max(width, height)
    if start_angle is None:
        # look at the walk from the side for a single view, then spread around
        path = joints[-1, JOINT_INDEX["pelvis"], :2] - joints[0, JOINT_INDEX["pelvis"], :2]
        heading = np.arctan2(path[1], path[0]) if np.linalg.norm(path) > 0.2 else 0.0
        start_angle = heading - np.pi / 2 + 0.35
    if radius is None:
        # The nearest ring at which every joint of every frame stays inside every view with a
        # margin: the body as large as the motion allows.
        pts = joints.reshape(-1, 3)[::7]
        conservative = max(body_h / (0.80 * height / focal_px),
                           (extent + 0.8) / (0.85 * width / focal_px), 2.5) + extent / 2
        radius = conservative
        for r in np.arange(1.8, conservative, 0.1):
            cams = ring_of_cameras(views, r, camera_height, target, (width, height), focal_px,
                                   start_angle=start_angle)
            if all(np.all(c.depth(pts) > 0.5) and _inside(c.project(pts), width, height, 0.06)
                   for c in cams):
                radius = r
                break
    rng = np.random.default_rng(seed + 17)
    backgrounds = [_background(rng, width, height, clutter) for _ in cams]
    body = synth_body(joints, joint_frames, build)
    return Scene(body, cams, backgrounds, noise=noise, seed=seed)


# -- takes on disk -----------------------------------------------------------------------------

def textured_grey(camera, seg2world, prims, textures, background, light, rng, noise=2.0):
    """A grey image of primitives wearing per-segment surface textures, Lambert-shaded.

    Parameters
    ----------
    camera : camera
    seg2world : array, shape (S, 4, 4)
    prims : primitives.Primitives
    textures : sequence of callable
        Per segment: grey level (0-255) of points given in the segment's coordinates.
    background : array (H, W) float
    light : array, shape (3,)
        Unit direction towards the light.
    rng : numpy.random.Generator
        Draws the sensor noise.
    noise : float
        Standard deviation of the sensor noise, grey levels.

    Returns
    -------
    array (H, W) uint8
    """
    res = render.render(camera, seg2world, prims, want=("point", "normal"))
    background = np.asarray(background)
    image = background.astype(np.result_type(background.dtype, np.float32))
    fg = res.label >= 0
    label = res.label[fg].astype(int)
    inv = np.linalg.inv(seg2world)[label]
    local = np.einsum("nij,nj->ni", inv[:, :3, :3], res.point[fg]) + inv[:, :3, 3]
    grey = np.zeros(len(label))
    for s in np.unique(label):
        grey[label == s] = textures[s](local[label == s])
    image[fg] = grey * (0.45 + 0.55 * np.clip(res.normal[fg] @ light, 0, 1))
    image += rng.normal(0.0, noise, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


# Everyday poses for synthetic subjects: half-range (degrees) per DOF without side prefix;
# knees and elbows bend one way only.
EVERYDAY_SPREAD_DEG = {"lumbar": 10, "thorax": 10, "neck": 20, "shoulder_flex": 45,
                       "shoulder_abd": 25, "shoulder_rot": 30, "elbow_flex": 70, "hip_flex": 40,
                       "hip_abd": 15, "hip_rot": 15, "knee_flex": 70, "ankle_flex": 20,
                       "ankle_inv": 10}


def everyday_pose(body, rng):
    """A random everyday pose of ``body``: upright, feet just above the floor, turned any way,
    within ``x`` metres of the origin (|x|, |y| <= 0.4)."""
    from ..geometry import se3
    from ..body.body import Pose

    spread = np.zeros(body.n_dofs)
    for k, name in enumerate(body.dof_names):
        bare = name[2:] if name[:2] in ("l_", "r_") else name
        spread[k] = np.radians(next((d for key, d in EVERYDAY_SPREAD_DEG.items()
                                     if bare.startswith(key)), 0.0))
    angles = np.clip(rng.uniform(-spread, spread), body.lower, body.upper)
    one_way = [k for k, n in enumerate(body.dof_names) if n.endswith(("knee_flex", "elbow_flex"))]
    angles[one_way] = rng.uniform(0.0, spread[one_way])
    root = se3.transform(se3.exp_so3([0.0, 0.0, rng.uniform(-np.pi, np.pi)]),
                         [rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), 0.0])
    root[2, 3] = 0.05 - body.joints(Pose(root, angles))[:, 2].min()
    return Pose(root, angles)


def random_subject(rng, template="full"):
    """A body of random size (0.9-1.1) whose lengths differ from the template's proportions
    by up to 5 %."""
    from ..body.body import DEFAULT_DIMS, LENGTH_DIMS, make_body

    size = rng.uniform(0.9, 1.1)
    return make_body(template, {n: DEFAULT_DIMS[n] * size * rng.uniform(0.95, 1.05)
                                for n in LENGTH_DIMS})


def project_joints(cameras, joints):
    """Ground-truth 2D joints per view: dict view -> array (F, 17, 2)."""
    return {cam.name: cam.project(joints) for cam in cameras}


def write_take(out, scene, joints, *, fps=30.0, image_format="png", marker_noise=0.0,
               anchors=(0,), source="", force=False, progress=None, cancel=None):
    """Render every frame of every view into ``out`` with calibration, truth and markers.

    Layout: ``out/<view>/000000.<fmt>`` image folders, ``calibration.json``, ``truth.json``
    (``zoopraxis-truth/1``: joints3d and per-view joints2d, the result.json layout) and
    ``markers.json`` with the true joints (plus ``marker_noise`` pixels of click noise) at the
    ``anchors`` frames.

    Parameters
    ----------
    progress : callable(done, total), optional
    cancel : callable() -> bool, optional
        Polled between frames; rendering stops early and the frames written stay.
    """
    from ..files.calibfile import write_calibration

    out = Path(out)
    if out.exists() and any(out.iterdir()) and not force:
        raise ZoopraxisError(f"{out}: folder exists and is not empty (use --force to replace it)")
    out.mkdir(parents=True, exist_ok=True)
    ext = {"png": ".png", "jpg": ".jpg", "jpeg": ".jpg"}.get(image_format)
    if ext is None:
        raise ZoopraxisError(f"unknown image format '{image_format}' (expected png or jpg)")
    params = [cv2.IMWRITE_JPEG_QUALITY, 92] if ext == ".jpg" else [cv2.IMWRITE_PNG_COMPRESSION, 3]
    total = scene.num_frames * len(scene.cameras)
    done = 0
    written = scene.num_frames
    for cam in scene.cameras:
        (out / cam.name).mkdir(exist_ok=True)
    for f in range(scene.num_frames):
        if cancel is not None and cancel():
            written = f
            break
        for v, cam in enumerate(scene.cameras):
            image, _ = scene.render_frame(f, v)
            cv2.imwrite(str(out / cam.name / f"{f:06d}{ext}"), image, params)
            done += 1
        if progress is not None:
            progress(done, total)
    joints = np.asarray(joints)[:written]
    write_calibration(out / "calibration.json", scene.cameras, force=True)
    proj = project_joints(scene.cameras, joints)
    truth = {"format": "zoopraxis-truth/1", "source": source, "fps": float(fps),
             "joints": list(STANDARD_JOINTS), "frames": list(range(written)),
             "joints3d": np.round(joints, 5).tolist(),
             "views": {name: {"joints2d": np.round(uv, 3).tolist()} for name, uv in proj.items()}}
    (out / "truth.json").write_text(json.dumps(truth))
    rng = np.random.default_rng(scene.seed + 99)
    markers = {"anchors": []}
    for a in anchors:
        if a >= written:
            continue
        views = {}
        for name, uv in proj.items():
            clicked = uv[a] + rng.normal(0.0, marker_noise, size=uv[a].shape) if marker_noise \
                else uv[a]
            views[name] = {j: [round(float(x), 2), round(float(y), 2)]
                           for j, (x, y) in zip(STANDARD_JOINTS, clicked)}
        markers["anchors"].append({"frame": int(a), "views": views})
    (out / "markers.json").write_text(json.dumps(markers, indent=1))
    return written


def read_truth(path):
    """Read a ``truth.json`` written by :func:`write_take`.

    Returns
    -------
    truth : dict
        ``joints3d`` (F, 17, 3) and ``joints2d`` {view: (F, 17, 2)} as arrays, plus ``fps`` and
        ``frames``.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ZoopraxisError(f"{path}: no such file") from None
    except json.JSONDecodeError as exc:
        raise ZoopraxisError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    for key in ("joints3d", "views", "fps", "frames"):
        if key not in data:
            raise ZoopraxisError(f"{path}: missing required key '{key}'")
    return {"fps": float(data["fps"]), "frames": list(data["frames"]),
            "joints3d": np.asarray(data["joints3d"], float),
            "joints2d": {v: np.asarray(d["joints2d"], float) for v, d in data["views"].items()}}


def take_from_bvh(bvh_path, *, frames=None, fps=30.0, **scene_options):
    """Load a CMU capture, cut ``frames`` (a range over the resampled motion), build a scene.

    Returns
    -------
    scene : Scene
    joints : array, shape (F, 17, 3)
    """
    from ..files import cmu

    motion = cmu.load_cmu(bvh_path, fps=fps)
    sel = None if frames is None else np.arange(motion.num_frames)[frames]
    if sel is not None and len(sel) == 0:
        raise ZoopraxisError(f"{bvh_path}: frame range {frames} is empty "
                             f"(the capture has {motion.num_frames} frames at {fps:g} fps)")
    joints = cmu.standard_joints(motion, frames=sel)
    jframes = cmu.standard_joint_frames(motion, frames=sel)
    return make_scene(joints, jframes, **scene_options), joints


__all__ = ["SynthBody", "Scene", "synth_body", "make_scene", "write_take", "read_truth",
           "project_joints", "take_from_bvh", "BUILDS"]


class ScenePlate:
    """A view of a synthetic scene behaving like a :class:`plates.Plate`, rendered on demand.

    Lets trackers and benchmarks run on synthetic takes without writing images to disk.
    """

    def __init__(self, scene, view, fps=30.0):
        self.scene = scene
        self.view = view
        self.name = scene.cameras[view].name
        self.path = f"<synthetic {self.name}>"
        self.fps = fps
        self.image_size = tuple(scene.cameras[view].image_size)
        self.num_frames = scene.num_frames

    def __len__(self):
        return self.num_frames

    def read(self, frame, *, gray=False, dtype=np.uint8):
        if not 0 <= frame < self.num_frames:
            raise ZoopraxisError(f"{self.path}: frame {frame} is outside 0-{self.num_frames - 1}")
        image, _ = self.scene.render_frame(frame, self.view)
        if gray:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        if dtype == np.float32:
            image = image.astype(np.float32) / 255.0
        return image


def scene_plates(scene, fps=30.0):
    """``{view name: ScenePlate}`` for every camera of a scene."""
    return {cam.name: ScenePlate(scene, v, fps) for v, cam in enumerate(scene.cameras)}
