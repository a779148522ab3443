"""Bulk keying through Blender 5's slotted actions, and rotation conversions for it.

One F-curve per channel, ``keyframe_points.add(n)`` once and ``foreach_set('co', ...)``; never
``keyframe_insert`` per frame. Every run keys into a new action (``bpy.data.actions.new`` adds
``.001`` to a taken name), so nothing the user keyed is ever replaced.
"""

import bpy
import numpy as np
from bpy_extras import anim_utils
from scipy.spatial.transform import Rotation

# KeyframePoint.interpolation as the integer foreach_set takes (the enum's order in RNA).
_INTERPOLATION = {'CONSTANT': 0, 'LINEAR': 1}


def new_action(obj, name):
    """Assign a new action with one slot for ``obj`` and return ``(action, channelbag)``.

    The object's previous action, if only this object used it, gets a fake user so that it
    survives a save: a new run never loses an old one.
    """
    adt = obj.animation_data_create()
    previous = adt.action
    if previous is not None and previous.users <= 1 and not previous.use_fake_user:
        previous.use_fake_user = True
    action = bpy.data.actions.new(name)
    action.use_fake_user = True
    slot = action.slots.new(obj.id_type, obj.name)
    adt.action = action
    adt.action_slot = slot
    return action, anim_utils.action_ensure_channelbag_for_slot(action, slot)


def key_channels(channelbag, data_path, times, values, *, group=None, interpolation='LINEAR'):
    """Key every column of ``values`` as one F-curve of ``data_path`` in one bulk assignment.

    Parameters
    ----------
    channelbag : bpy.types.ActionChannelbag
    data_path : str
    times : array, shape (F,)
        Scene frames.
    values : array, shape (F,) or (F, C)
        Column ``i`` goes to array index ``i``.
    group : str, optional
        F-curve group (the bone name for bone channels).
    interpolation : {'LINEAR', 'CONSTANT'}
    """
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    times = np.asarray(times, dtype=float)
    n = len(times)
    co = np.empty(2 * n)
    co[0::2] = times
    mode = [_INTERPOLATION[interpolation]] * n
    curves = []
    for index in range(values.shape[1]):
        kwargs = {"group_name": group} if group else {}
        fcurve = channelbag.fcurves.new(data_path, index=index, **kwargs)
        points = fcurve.keyframe_points
        points.add(n)
        co[1::2] = values[:, index]
        points.foreach_set("co", co)
        points.foreach_set("interpolation", mode)
        fcurve.update()
        curves.append(fcurve)
    return curves


def quaternions_from_matrices(R):
    """Blender quaternions ``(w, x, y, z)`` of rotation matrices, with sign continuity.

    Convention: scipy's scalar-last quaternion reordered scalar-first (mathutils'). ``q`` and
    ``-q`` are the same rotation; each is flipped to the sign nearer its predecessor so the
    F-curves interpolate along the short way, and the first has ``w >= 0``.

    Parameters
    ----------
    R : array, shape (F, 3, 3)

    Returns
    -------
    q : array, shape (F, 4)
    """
    xyzw = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    if len(q) == 0:
        return q
    flips = np.ones(len(q))
    flips[0] = -1.0 if q[0, 0] < 0 else 1.0
    flips[1:] = np.where(np.sum(q[1:] * q[:-1], axis=1) < 0, -1.0, 1.0)
    return q * np.cumprod(flips)[:, None]


def eulers_from_matrices(R, order):
    """Euler angles of rotation matrices in a Blender rotation mode, continuous over frames.

    Convention: Blender's ``to_euler(order, previous)``, which picks among the equivalent
    triples the one nearest the previous frame's.

    Parameters
    ----------
    R : array, shape (F, 3, 3)
    order : str
        'XYZ', 'ZXY', ... (a pose bone's ``rotation_mode``).

    Returns
    -------
    angles : array, shape (F, 3)
    """
    from mathutils import Euler, Matrix

    out = np.empty((len(R), 3))
    previous = Euler((0.0, 0.0, 0.0), order)
    for i, m in enumerate(R):
        previous = Matrix(m.tolist()).to_euler(order, previous)
        out[i] = previous[:]
    return out


def key_rotation(channelbag, pose_bone, times, R):
    """Key a pose bone's rotation in its own rotation mode from basis matrices (F, 3, 3)."""
    from ..core.errors import ZoopraxisError

    path = f'pose.bones["{bpy.utils.escape_identifier(pose_bone.name)}"]'
    mode = pose_bone.rotation_mode
    if mode == 'QUATERNION':
        key_channels(channelbag, path + ".rotation_quaternion", times,
                     quaternions_from_matrices(R), group=pose_bone.name)
    elif mode == 'AXIS_ANGLE':
        rotvec = Rotation.from_matrix(R).as_rotvec()
        angle = np.linalg.norm(rotvec, axis=1)
        axis = np.where(angle[:, None] > 1e-12, rotvec / np.maximum(angle, 1e-12)[:, None],
                        [0.0, 1.0, 0.0])
        key_channels(channelbag, path + ".rotation_axis_angle", times,
                     np.column_stack([angle, axis]), group=pose_bone.name)
    elif len(mode) == 3:
        key_channels(channelbag, path + ".rotation_euler", times, eulers_from_matrices(R, mode),
                     group=pose_bone.name)
    else:
        raise ZoopraxisError(f"bone '{pose_bone.name}': unknown rotation mode {mode}")


def key_location(channelbag, pose_bone, times, locations):
    path = f'pose.bones["{bpy.utils.escape_identifier(pose_bone.name)}"].location'
    key_channels(channelbag, path, times, locations, group=pose_bone.name)
