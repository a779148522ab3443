"""Foundation numbers: the renderer's time per 640x480 view and the size of the built zip.

    .venv/bin/python benchmarks/bench_foundation.py
"""

import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_render.py")], check=True)
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, str(ROOT / "tools" / "build_extension.py"),
                        "--output-dir", tmp], check=True, capture_output=True)
        (zip_path,) = Path(tmp).glob("*.zip")
        with zipfile.ZipFile(zip_path) as z:
            n = len(z.namelist())
        print(f"extension zip: {zip_path.name}, {zip_path.stat().st_size / 1024:.1f} kB, "
              f"{n} files (without bundled scipy/OpenCV wheels)")


if __name__ == "__main__":
    main()
