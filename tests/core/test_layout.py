"""The layout of the package, checked statically: core never names the add-on or Blender, no module
is too long, and every folder of core says what lives in it.

The checks read the source with ``ast`` and import nothing, so an import hidden in a function
(which a test importing the module would never run) is caught too.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CORE = ROOT / "core"
ADDON = ROOT / "addon"

# Top-level modules core may never import: the add-on (by any relative or absolute path) and
# Blender's own.
FORBIDDEN = ("addon", "bpy", "mathutils", "bmesh", "bpy_extras")

MAX_LINES = 800

def forbidden_imports(source, package_depth, filename="<string>"):
    """The forbidden imports of a module's source, as ``(line, name)`` pairs.

    Parameters
    ----------
    source : str
        Python source of a module under core/.
    package_depth : int
        How many packages deep the module sits below the repository root (the root package
        ``zoopraxis``): 2 for ``core/geometry/camera.py``. A relative import with more dots than
        that climbs out of core, to the root package, and names whatever follows.
    filename : str
        For syntax errors.

    Returns
    -------
    found : list of (int, str)
        The line and the dotted name of each import of a forbidden module.
    """
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level == 0:
                names = [module]
            elif node.level > package_depth:
                # From the root package: "from ... import addon" or "from ...addon import x".
                names = [module] if module else [alias.name for alias in node.names]
            else:
                continue
        else:
            continue
        for name in names:
            parts = name.split(".")
            if parts[0] == "zoopraxis":
                parts = parts[1:]
            if parts and parts[0] in FORBIDDEN:
                found.append((node.lineno, name))
    return found


def core_modules():
    return sorted(CORE.rglob("*.py"))


def test_core_never_imports_the_addon_or_blender():
    bad = []
    for path in core_modules():
        depth = len(path.relative_to(ROOT).parts) - 1
        for line, name in forbidden_imports(path.read_text(), depth, str(path)):
            bad.append(f"{path.relative_to(ROOT)}:{line}: imports {name}")
    assert not bad, "core must not name the add-on or Blender:\n" + "\n".join(bad)


@pytest.mark.parametrize("source", [
    "import bpy",
    "import bmesh.ops",
    "from mathutils import Matrix",
    "from bpy_extras.io_utils import ImportHelper",
    "import zoopraxis.addon.bake",
    "from zoopraxis.addon import bake",
    "from ...addon import bake",
    "from ... import addon",
    "def later():\n    from ...addon.bake import bake_take\n",
    "class A:\n    def f(self):\n        import bpy\n",
])
def test_the_check_catches_every_form_of_forbidden_import(source):
    # As if in core/<stage>/module.py: two packages below the root.
    found = forbidden_imports(source, package_depth=2)
    assert len(found) == 1 and found[0][0] == source.count("\n", 0, source.rfind("import")) + 1


@pytest.mark.parametrize("source", [
    "import numpy",
    "from ..geometry import camera",
    "from .. import errors",
    "from . import addon_helpers",
    "from ..bake import addon",          # a sibling stage's module, inside core
    "import bpyish",
])
def test_the_check_lets_core_imports_through(source):
    assert forbidden_imports(source, package_depth=2) == []


def test_no_module_is_too_long():
    long = []
    for path in sorted([*CORE.rglob("*.py"), *ADDON.rglob("*.py")]):
        name = path.relative_to(ROOT).as_posix()
        lines = len(path.read_text().splitlines())
        if lines > MAX_LINES:
            long.append(f"{name}: {lines} lines")
    assert not long, f"modules over {MAX_LINES} lines (split them along their jobs):\n" + \
        "\n".join(long)


def test_every_folder_of_core_has_a_package_docstring():
    missing = []
    for folder in sorted(p for p in [CORE, *CORE.rglob("*")] if p.is_dir()):
        if folder.name == "__pycache__" or not any(folder.glob("*.py")):
            continue
        init = folder / "__init__.py"
        if not init.is_file() or not ast.get_docstring(ast.parse(init.read_text())):
            missing.append(folder.relative_to(ROOT).as_posix())
    assert not missing, "folders of core without an __init__.py with a docstring:\n" + \
        "\n".join(missing)
