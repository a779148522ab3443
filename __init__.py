"""Zoopraxis: markerless motion capture from camera plates, as a Blender extension.

Nothing here imports bpy at module level, so ``python -m zoopraxis`` and the pure
``core`` package work on a machine without Blender.
"""


def register():
    from .addon import registration

    registration.register()


def unregister():
    from .addon import registration

    registration.unregister()
