"""The extension as Blender sees it: the built zip, install/enable/disable, registration."""

import json
import os
import subprocess
import sys
import textwrap
import types
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tools"))
import build_extension  # noqa: E402

# Installing into Blender's "User Default" repository names the package after it.
EXTENSION_MODULE = "bl_ext.user_default.zoopraxis"


def run_python(code, env=None, cwd=None):
    """Run ``code`` in a fresh interpreter: bpy reads its environment once, at import."""
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, env=env, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory):
    out = tmp_path_factory.mktemp("build")
    result = subprocess.run([sys.executable, str(REPO / "tools" / "build_extension.py"),
                             "--output-dir", str(out)], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    printed_path, size, unit = result.stdout.split()
    path = out / "zoopraxis-0.1.0.zip"
    assert (printed_path, unit) == (str(path), "kB")
    assert float(size) == pytest.approx(path.stat().st_size / 1024, abs=0.05)
    return path


def test_manifest_passes_blender_validator(tmp_path):
    tags = build_extension.write_valid_tags(tmp_path / "tags.json")
    result = subprocess.run([sys.executable, str(build_extension.builder_path()), "validate",
                             "--valid-tags", str(tags), str(REPO)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "FATAL" not in result.stdout + result.stderr


def test_zip_holds_extension_and_no_development_files(built_zip):
    names = zipfile.ZipFile(built_zip).namelist()
    assert {"blender_manifest.toml", "__init__.py", "cli.py", "__main__.py",
            "addon/registration.py", "addon/preferences.py", "core/errors.py"} <= set(names)
    # the learned priors the trackers and the initialization use by default
    assert {f"core/priors/data/{name}.npz" for name in (
        "motion_prior", "pose_prior", "walk_prior", "proportions_prior")} <= set(names)
    assert any(name.startswith("core/") for name in names)
    leaked = [name for name in names if name.split("/")[0] in (
        "tests", "benchmarks", "tools", ".venv", ".ci", ".git", "wheels", "out")
        or "__pycache__" in name or ".egg-info" in name
        or name in ("pyproject.toml", "requirements.txt", ".gitignore")]
    assert leaked == []


def test_wheel_build_lists_wheels_in_copied_manifest(tmp_path):
    # Stand-in wheel files with the real names pip resolves: the builder only packs them,
    # so this exercises the --with-wheels path without downloading hundreds of MB.
    names = ["scipy-1.17.1-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl",
             "scipy-1.17.1-cp311-cp311-macosx_12_0_arm64.whl",
             "scipy-1.17.1-cp311-cp311-win_amd64.whl",
             "opencv_python_headless-4.11.0.86-cp37-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
             "opencv_python_headless-4.11.0.86-cp37-abi3-macosx_13_0_arm64.whl",
             "opencv_python_headless-4.11.0.86-cp37-abi3-win_amd64.whl"]
    wheels = []
    for name in names:
        (tmp_path / name).write_bytes(b"stand-in")
        wheels.append(tmp_path / name)
    manifest_before = (REPO / "blender_manifest.toml").read_text()
    had_wheels_dir = (REPO / "wheels").exists()

    [path] = build_extension.build(tmp_path / "out", wheels)

    # The checkout is left alone: the wheels go into a temporary copy of the source.
    assert (REPO / "blender_manifest.toml").read_text() == manifest_before
    assert (REPO / "wheels").exists() == had_wheels_dir
    with zipfile.ZipFile(path) as archive:
        assert {f"wheels/{name}" for name in names} <= set(archive.namelist())
        manifest = archive.read("blender_manifest.toml").decode()
    assert all(f'"./wheels/{name}"' in manifest for name in names)
    assert 'platforms = ["linux-x64", "macos-arm64", "windows-x64"]' in manifest

    split = build_extension.build(tmp_path / "split", wheels, split_platforms=True)
    with zipfile.ZipFile(split[0]) as archive:
        assert sorted(n for n in archive.namelist() if n.endswith(".whl")) == [
            f"wheels/{names[3]}", f"wheels/{names[0]}"]


def test_pip_download_fetches_pinned_binaries_for_each_platform(tmp_path):
    commands = build_extension.pip_download_commands(tmp_path)
    assert len(commands) == 3
    for command in commands:
        assert command[1:4] == ["-m", "pip", "download"]
        assert "--only-binary=:all:" in command and "--no-deps" in command
        assert command[command.index("--python-version") + 1] == "3.11"
        assert command[command.index("--dest") + 1] == str(tmp_path)
        assert command[-2:] == ["scipy==1.17.1", "opencv-python-headless==4.11.0.86"]
    platforms = [[c[i + 1] for i, a in enumerate(c) if a == "--platform"] for c in commands]
    assert "manylinux_2_28_x86_64" in platforms[0]
    assert platforms[1] == ["macosx_13_0_arm64"] and platforms[2] == ["win_amd64"]


def test_install_enable_disable_in_blender(built_zip, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender"))
    result = run_python(f"""
        import json, sys
        import bpy

        name = {EXTENSION_MODULE!r}
        report = {{}}

        def cli_registered():
            # Blender warns when an id is taken; a fresh handle is removed again at once.
            sys.stdout.flush()
            handle = bpy.utils.register_cli_command("zoopraxis", lambda argv: 0)
            bpy.utils.unregister_cli_command(handle)

        bpy.ops.extensions.package_install_files(
            filepath={str(built_zip)!r}, repo="user_default", enable_on_install=True)
        addon = bpy.context.preferences.addons.get(name)
        report["enabled"] = addon is not None
        report["prefs_idname"] = type(addon.preferences).bl_idname if addon else None
        report["prefs_tracker"] = addon.preferences.default_tracker if addon else None
        registration = sys.modules[name + ".addon.registration"]
        preferences = sys.modules[name + ".addon.preferences"]
        report["registered"] = registration.is_registered()
        report["cli_exit"] = registration._cli_command(["info"])
        print("<<enabled>>"); cli_registered()

        bpy.ops.preferences.addon_disable(module=name)
        report["enabled_after"] = name in bpy.context.preferences.addons
        report["registered_after"] = registration.is_registered()
        report["prefs_class_after"] = preferences.ZOOPRAXIS_AddonPreferences.is_registered
        print("<<disabled>>"); cli_registered()
        print("<<report>>" + json.dumps(report))
    """, env=env, cwd=tmp_path)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    report = json.loads(result.stdout.split("<<report>>")[1])
    assert report == {"enabled": True, "prefs_idname": EXTENSION_MODULE,
                      "prefs_tracker": "DIFFERENTIAL", "registered": True, "cli_exit": 0,
                      "enabled_after": False, "registered_after": False,
                      "prefs_class_after": False}
    assert f"{tmp_path}/blender/extensions/user_default/zoopraxis" in result.stdout
    enabled, disabled = result.stdout.split("<<enabled>>")[1].split("<<disabled>>")
    duplicate = 'duplicate command "zoopraxis"'
    # The C warning may go to either stream; stdout carries the markers, stderr the rest.
    assert duplicate in enabled or result.stderr.count(duplicate) == 1, output
    assert duplicate not in disabled.split("<<report>>")[0]
    assert result.stderr.count(duplicate) + result.stdout.count(duplicate) == 1, output


def test_package_imports_without_bpy():
    result = run_python("""
        import importlib, pkgutil, sys
        import zoopraxis, zoopraxis.cli, zoopraxis.core
        imported = []
        for module in pkgutil.walk_packages(zoopraxis.core.__path__, "zoopraxis.core."):
            try:
                importlib.import_module(module.name)
                imported.append(module.name.removeprefix("zoopraxis.core."))
            except Exception:
                # A module half-written elsewhere fails its own tests; importing bpy
                # before failing would still show up in sys.modules below.
                pass
        print(sorted(m for m in ("bpy", "mathutils", "bmesh") if m in sys.modules))
        print(sorted(imported))
    """)
    assert result.returncode == 0, result.stderr
    leaked, imported = result.stdout.strip().splitlines()
    assert leaked == "[]"
    assert "errors" in imported and "body.joints" in imported and "take.track" in imported


@pytest.fixture
def registration():
    bpy = pytest.importorskip("bpy")
    from zoopraxis.addon import registration

    yield registration
    if registration.is_registered():
        registration.unregister()
    assert bpy is not None


def cli_command_taken(capfd, bpy):
    capfd.readouterr()
    handle = bpy.utils.register_cli_command("zoopraxis", lambda argv: 0)
    bpy.utils.unregister_cli_command(handle)
    captured = capfd.readouterr()
    return 'duplicate command "zoopraxis"' in captured.out + captured.err


def test_register_unregister_register_in_tree(registration, capfd):
    import bpy
    import zoopraxis
    from zoopraxis.addon.preferences import ZOOPRAXIS_AddonPreferences

    assert ZOOPRAXIS_AddonPreferences.bl_idname == "zoopraxis"
    for _ in range(2):
        zoopraxis.register()
        assert ZOOPRAXIS_AddonPreferences.is_registered
        assert cli_command_taken(capfd, bpy)
        assert registration._cli_command(["info"]) == 0
        zoopraxis.unregister()
        assert not ZOOPRAXIS_AddonPreferences.is_registered
        assert not cli_command_taken(capfd, bpy)
        assert not registration.is_registered()


def test_modules_register_in_order_and_unregister_in_reverse(registration, monkeypatch):
    import bpy

    calls = []

    class ZOOPRAXIS_OT_probe(bpy.types.Operator):
        """Probe operator for the registration test"""
        bl_idname = "zoopraxis.probe"
        bl_label = "Probe"

    def fake_module(name, classes=()):
        module = types.ModuleType(f"zoopraxis.addon.{name}")
        module.classes = classes
        module.register = lambda: calls.append(("register", name))
        module.unregister = lambda: calls.append(("unregister", name))
        monkeypatch.setitem(sys.modules, module.__name__, module)
        return name

    monkeypatch.setattr(registration, "MODULES", (fake_module("first", (ZOOPRAXIS_OT_probe,)),
                                                  fake_module("second")))
    registration.register()
    assert ZOOPRAXIS_OT_probe.is_registered and hasattr(bpy.ops.zoopraxis, "probe")
    registration.unregister()
    assert not ZOOPRAXIS_OT_probe.is_registered
    assert calls == [("register", "first"), ("register", "second"),
                     ("unregister", "second"), ("unregister", "first")]


def test_failed_register_leaves_nothing_behind(registration, monkeypatch, capfd):
    import bpy
    from zoopraxis.addon.preferences import ZOOPRAXIS_AddonPreferences

    broken = types.ModuleType("zoopraxis.addon.broken")

    def fail():
        raise RuntimeError("broken hook")

    broken.register = fail
    monkeypatch.setitem(sys.modules, broken.__name__, broken)
    monkeypatch.setattr(registration, "MODULES", ("broken",))
    with pytest.raises(RuntimeError, match="broken hook"):
        registration.register()
    assert not registration.is_registered()
    assert not ZOOPRAXIS_AddonPreferences.is_registered
    assert not cli_command_taken(capfd, bpy)

    monkeypatch.setattr(registration, "MODULES", ())
    registration.register()
    assert ZOOPRAXIS_AddonPreferences.is_registered
