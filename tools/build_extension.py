"""Build the Zoopraxis extension zip with Blender's own extension builder.

    .venv/bin/python tools/build_extension.py [--output-dir DIR] [--with-wheels]

Blender bundles numpy but not scipy or OpenCV. ``--with-wheels`` downloads the pinned
wheels of both for Blender's Python (3.11) on Linux x86_64, macOS arm64 and Windows
x86_64 and lists them in the manifest of a temporary copy of the source, so the zip
installs them inside Blender. Without it the zip holds only the extension's own code.
"""

import argparse
import ast
import importlib.util
import json
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# Pinned like requirements.txt; numpy is left out because Blender ships its own.
WHEEL_REQUIREMENTS = ("scipy==1.17.1", "opencv-python-headless==4.11.0.86")

# pip tags per Blender platform. pip does not widen manylinux_2_x tags by itself, so the
# glibc levels up to Blender 5.0's minimum (2.28) are listed; a macOS tag covers itself and
# older releases.
WHEEL_PLATFORMS = {
    "linux-x64": ("manylinux_2_28_x86_64", "manylinux_2_27_x86_64",
                  "manylinux_2_17_x86_64", "manylinux2014_x86_64"),
    "macos-arm64": ("macosx_13_0_arm64",),
    "windows-x64": ("win_amd64",),
}

# Not worth copying into the temporary source tree; the manifest's own exclusions still apply.
COPY_IGNORE = shutil.ignore_patterns(
    ".git", ".venv", "__pycache__", ".pytest_cache", "*.egg-info", "out", "wheels", "dist", "build",
    "*.zip")


def blender_scripts_dir():
    """Return the ``scripts`` folder of the installed ``bpy`` module, without importing bpy."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("build_extension: the bpy module is not installed (run tools/setup.sh first)")
    found = sorted(Path(spec.submodule_search_locations[0]).glob("*/scripts"))
    if not found:
        sys.exit("build_extension: bpy has no scripts folder")
    return found[-1]


def builder_path():
    """Return the path of Blender's ``blender_ext.py`` command-line builder."""
    return blender_scripts_dir() / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"


def write_valid_tags(path):
    """Write Blender's list of extension tags as the JSON the builder validates against."""
    source = (blender_scripts_dir() / "modules" / "_bpy_internal" / "extensions" / "tags.py").read_text()
    tags = {}
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name):
            tags[node.targets[0].id] = sorted(ast.literal_eval(node.value))
    # The builder keys tags by the manifest's type ("add-on"), tags.py by plural names.
    path.write_text(json.dumps({"add-on": tags["addons"], "theme": tags["themes"]}))
    return path


def pip_download_commands(wheels_dir):
    """Return one ``pip download`` argv per platform, fetching binary wheels only."""
    commands = []
    for platform_tags in WHEEL_PLATFORMS.values():
        command = [sys.executable, "-m", "pip", "download", "--only-binary=:all:", "--no-deps",
                   "--python-version", "3.11", "--implementation", "cp",
                   "--abi", "cp311", "--abi", "abi3", "--abi", "none",
                   "--dest", str(wheels_dir)]
        for tag in platform_tags:
            command += ["--platform", tag]
        commands.append(command + list(WHEEL_REQUIREMENTS))
    return commands


def manifest_with_wheels(text, wheel_names):
    """Return manifest ``text`` with ``wheels`` and ``platforms`` for the bundled wheels.

    Top-level keys must come before the first TOML table, so they go just above it.
    """
    lines = text.splitlines(keepends=True)
    first_table = next((i for i, line in enumerate(lines) if line.lstrip().startswith("[")
                        and not line.lstrip().startswith("[[") and "=" not in line), len(lines))
    added = ["platforms = [" + ", ".join(f'"{p}"' for p in WHEEL_PLATFORMS) + "]\n",
             "wheels = [\n", *(f'  "./wheels/{name}",\n' for name in wheel_names), "]\n", "\n"]
    result = "".join(lines[:first_table] + added + lines[first_table:])
    if tomllib.loads(result).get("wheels") != [f"./wheels/{name}" for name in wheel_names]:
        sys.exit("build_extension: could not add the wheels to blender_manifest.toml")
    return result


def run_builder(source_dir, output_path, split_platforms=False):
    """Build ``output_path`` from ``source_dir`` with Blender's builder; exit on failure."""
    with tempfile.TemporaryDirectory() as scratch:
        tags = write_valid_tags(Path(scratch) / "tags.json")
        command = [sys.executable, str(builder_path()), "build", "--source-dir", str(source_dir),
                   "--output-filepath", str(output_path), "--valid-tags", str(tags)]
        if split_platforms:
            command.append("--split-platforms")
        result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(result.stdout + result.stderr)
        sys.exit(f"build_extension: Blender's builder failed on {source_dir}")


def build(output_dir, wheels=None, split_platforms=False):
    """Build the extension zip into ``output_dir`` and return the paths of the zips.

    Parameters
    ----------
    output_dir : Path
        Folder for the zip, created if missing.
    wheels : list of Path, optional
        Wheel files to bundle. The source is then copied to a temporary folder whose
        manifest lists them, so the checkout itself is never modified.
    split_platforms : bool
        With wheels, build one zip per platform holding only that platform's wheels.
    """
    with (REPO / "blender_manifest.toml").open("rb") as file:
        manifest = tomllib.load(file)
    output_dir.mkdir(parents=True, exist_ok=True)
    suffix = "-wheels" if wheels else ""
    output_path = output_dir / f"{manifest['id']}-{manifest['version']}{suffix}.zip"
    if not wheels:
        run_builder(REPO, output_path)
        return [output_path]
    with tempfile.TemporaryDirectory() as scratch:
        source = Path(scratch) / "zoopraxis"
        shutil.copytree(REPO, source, ignore=COPY_IGNORE)
        (source / "wheels").mkdir()
        for wheel in wheels:
            shutil.copy2(wheel, source / "wheels" / wheel.name)
        text = (source / "blender_manifest.toml").read_text()
        # The wheels folder is excluded from plain builds; listed wheels are always packed.
        text = manifest_with_wheels(text, sorted(wheel.name for wheel in wheels))
        (source / "blender_manifest.toml").write_text(text)
        run_builder(source, output_path, split_platforms)
    if split_platforms:
        # The builder names each zip after the platform, with "_" for "-".
        return [output_path.with_name(f"{output_path.stem}-{platform.replace('-', '_')}.zip")
                for platform in WHEEL_PLATFORMS]
    return [output_path]


def download_wheels(wheels_dir):
    """Download the pinned wheels for every platform into ``wheels_dir``; return their paths."""
    wheels_dir.mkdir(parents=True, exist_ok=True)
    for command in pip_download_commands(wheels_dir):
        subprocess.run(command, check=True)
    names = {f"{requirement.split('==')[0].replace('-', '_')}-{requirement.split('==')[1]}-"
             for requirement in WHEEL_REQUIREMENTS}
    return sorted(path for path in wheels_dir.glob("*.whl")
                  if any(path.name.lower().startswith(name.lower()) for name in names))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output-dir", type=Path, default=REPO / "dist",
                        help="folder for the zip (default: dist/ in the repository)")
    parser.add_argument("--with-wheels", action="store_true",
                        help="bundle scipy and OpenCV wheels for Linux, macOS arm64 and Windows")
    parser.add_argument("--split-platforms", action="store_true",
                        help="with --with-wheels, one smaller zip per platform")
    parser.add_argument("--wheels-dir", type=Path, default=REPO / "dist" / "wheels",
                        help="where downloaded wheels are kept between builds (default: dist/wheels/)")
    args = parser.parse_args(argv)
    if args.split_platforms and not args.with_wheels:
        parser.error("--split-platforms needs --with-wheels: without wheels the zip fits every platform")
    wheels = download_wheels(args.wheels_dir.resolve()) if args.with_wheels else None
    for path in build(args.output_dir.resolve(), wheels, args.split_platforms):
        print(f"{path} {path.stat().st_size / 1024:.1f} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
