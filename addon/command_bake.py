"""``zoopraxis bake``: key a tracked take onto an armature and write .blend, BVH and FBX files.

Needs the ``bpy`` module (or Blender itself, through ``blender --background --command``); it is
imported only when the command runs.
"""

import argparse

from ..core.errors import ZoopraxisError


def build_parser():
    p = argparse.ArgumentParser(
        prog="zoopraxis bake",
        description="Build an armature from the fitted body of result.json, key its joint "
                    "angles, and write the take as .blend, BVH and/or FBX.")
    p.add_argument("--result", required=True, help="result.json written by 'zoopraxis track'")
    p.add_argument("--blend", help="write the baked scene to this .blend file")
    p.add_argument("--bvh", help="export the armature's motion to this BVH file")
    p.add_argument("--fbx", help="export the armature, body mesh and motion to this FBX file")
    p.add_argument("--name", help="take name for the action (default: the result file's stem)")
    p.add_argument("--force", action="store_true", help="replace existing output files")
    return p


def main(argv):
    args = build_parser().parse_args(argv)
    if not (args.blend or args.bvh or args.fbx):
        raise ZoopraxisError("nothing to write: give --blend, --bvh and/or --fbx")
    try:
        from . import bake
    except ImportError as ex:
        raise ZoopraxisError(f"bake needs Blender's bpy module ({ex})") from None
    written = bake.bake_file(args.result, blend=args.blend, bvh=args.bvh, fbx=args.fbx,
                             force=args.force, name=args.name)
    print(f"zoopraxis bake: wrote {', '.join(str(p) for p in written)}")
    return 0
