"""Register and unregister the whole extension with Blender.

Each name in ``MODULES`` is a module of this package that exposes ``classes = (...)``
and, optionally, ``register()`` / ``unregister()`` hooks for what is not a class (menu
entries, handlers, pointer properties). Modules are registered in the order listed and
unregistered in reverse, so list a module after the ones whose classes it refers to.
"""

import importlib

import bpy

from . import preferences

MODULES = ("props", "operators", "panels", "overlay")

CLI_COMMAND = "zoopraxis"

# Undo actions for everything registered so far, last first to run. Registering through
# this stack means a failure half-way is rolled back and unregister() leaves nothing behind.
_undo = []


def _cli_command(argv):
    """Run ``blender --command zoopraxis ARGS``: the same front as ``python -m zoopraxis``."""
    from .. import cli

    return cli.main(argv)


def _register_class(cls):
    bpy.utils.register_class(cls)
    _undo.append(lambda: bpy.utils.unregister_class(cls))


def _register_module(module):
    for cls in getattr(module, "classes", ()):
        _register_class(cls)
    hook = getattr(module, "register", None)
    if hook is not None:
        hook()
    unhook = getattr(module, "unregister", None)
    if unhook is not None:
        _undo.append(unhook)


def _register_all():
    _register_module(preferences)
    for name in MODULES:
        _register_module(importlib.import_module("." + name, __package__))
    handle = bpy.utils.register_cli_command(CLI_COMMAND, _cli_command)
    _undo.append(lambda: bpy.utils.unregister_cli_command(handle))


def register():
    if _undo:
        raise RuntimeError("Zoopraxis is already registered")
    try:
        _register_all()
    except BaseException as ex:
        try:
            unregister()
        except Exception as rollback_ex:
            # The failure to register is the one the user must see; the rollback's rides along.
            ex.add_note(f"while rolling back: {rollback_ex!r}")
        raise


def unregister():
    errors = []
    while _undo:
        try:
            _undo.pop()()
        except Exception as ex:
            # Keep going so one faulty hook does not strand everything registered before it.
            errors.append(ex)
    if errors:
        raise errors[0]


def is_registered():
    """Return True while the extension's classes and command are registered."""
    return bool(_undo)
