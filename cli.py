"""The command line: ``python -m zoopraxis COMMAND ...`` and ``blender --command zoopraxis COMMAND ...``.

Commands live in ``COMMANDS``: name -> (module, function, one-line help). The module path
is relative to this package and imported only when its command runs, so ``info`` never
pays for the tracker and a command that needs ``bpy`` does not load it for the others.
A handler takes the arguments after its name and returns an exit code (None means 0).

Exit codes: 0 success, 2 bad input (a ``ZoopraxisError``, printed on one line, or an
unknown command), 130 cancelled with Ctrl-C; whatever a command already wrote stays.
"""

import importlib
import importlib.util
import sys

from .core.errors import ZoopraxisError

PROG = "zoopraxis"

COMMANDS = {
    "info": ("cli", "info", "print the versions of Zoopraxis, Python and its dependencies"),
    "synth": ("core.commands.synth", "main",
              "render synthetic plates from motion capture, with ground truth and markers"),
    "track": ("core.commands.track", "main",
              "track a body through plates from clicked joints and write result.json"),
    "demo": ("core.commands.demo", "main", "run the whole pipeline on the bundled sample"),
    "bake": ("addon.command_bake", "main", "key a tracked take onto an armature; write .blend, BVH, FBX"),
    "calibrate": ("core.commands.calibrate", "main", "calibrate the cameras from a board in the plates"),
    "init": ("core.commands.init", "main", "fit the body to the clicked joints of the anchor frames"),
    "prior": ("core.commands.prior", "main",
              "learn the pose prior of one-view frames from captures or tracks of a motion"),
}


def usage():
    """Return the top-level help text listing the commands."""
    width = max(len(name) for name in COMMANDS)
    lines = [f"usage: {PROG} COMMAND [ARGS ...]", "", "commands:"]
    lines += [f"  {name:<{width}}  {COMMANDS[name][2]}" for name in sorted(COMMANDS)]
    lines += ["", f"Run '{PROG} COMMAND --help' for the arguments of one command."]
    return "\n".join(lines)


def _one_line(message):
    return " ".join(str(message).split("\n")).strip()


def _exit_code(code):
    # sys.exit(None) is success and sys.exit("text") a failure, as in the interpreter.
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1


def main(argv=None):
    """Run one command and return its exit code.

    Parameters
    ----------
    argv : list of str, optional
        The command name and its arguments; ``sys.argv[1:]`` by default.

    Returns
    -------
    code : int
        The process exit code. ``main`` never calls ``sys.exit`` itself, because inside
        Blender that would end Blender rather than the command.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage(), file=sys.stdout if argv else sys.stderr)
        return 0 if argv else 2

    name, args = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"{PROG}: error: unknown command '{name}' (available: {', '.join(sorted(COMMANDS))})",
              file=sys.stderr)
        return 2

    module_name, function_name, _ = COMMANDS[name]
    try:
        handler = getattr(importlib.import_module("." + module_name, __package__), function_name)
        return _exit_code(handler(args))
    except ZoopraxisError as ex:
        print(f"{PROG} {name}: error: {_one_line(ex)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG} {name}: cancelled", file=sys.stderr)
        return 130
    except SystemExit as ex:
        # argparse exits on --help and on malformed arguments; turn that into a return code.
        return _exit_code(ex.code)


def manifest_version():
    """Return the extension version from ``blender_manifest.toml`` beside this file."""
    import tomllib
    from pathlib import Path

    path = Path(__file__).with_name("blender_manifest.toml")
    try:
        with path.open("rb") as file:
            manifest = tomllib.load(file)
    except (OSError, tomllib.TOMLDecodeError) as ex:
        raise ZoopraxisError(f"{path}: cannot read the extension manifest ({ex})") from None
    if "version" not in manifest:
        raise ZoopraxisError(f"{path}: missing required key 'version'")
    return manifest["version"]


def _module_version(module_name):
    try:
        module = importlib.import_module(module_name)
    except ImportError:
        return "missing"
    return getattr(module, "__version__", "unknown version")


def _bpy_status():
    # Report bpy without importing it: importing starts a whole Blender session.
    if "bpy" in sys.modules:
        return "running inside Blender " + sys.modules["bpy"].app.version_string
    if importlib.util.find_spec("bpy") is None:
        return "not importable"
    try:
        from importlib.metadata import version

        return f"importable ({version('bpy')})"
    except Exception:
        return "importable"


def info(argv):
    """Print the versions of Zoopraxis, Python and the numerical dependencies."""
    import argparse
    import platform
    from pathlib import Path

    parser = argparse.ArgumentParser(prog=f"{PROG} info", description=info.__doc__)
    parser.parse_args(argv)
    print(f"zoopraxis {manifest_version()} ({Path(__file__).resolve().parent})")
    print(f"python {platform.python_version()} ({sys.executable})")
    for module_name, label in (("numpy", "numpy"), ("scipy", "scipy"), ("cv2", "opencv")):
        print(f"{label} {_module_version(module_name)}")
    print(f"bpy {_bpy_status()}")
    return 0
