"""What `pip install 'spinefarm[EXTRAS]'` puts on disk: a fresh venv per extras set, its size, its largest packages.

    python bench/install_size.py                       # all, all+parquet, all+video
    python bench/install_size.py --extras api worker   # chosen sets

Prints one JSON object: per extras set the venv's size in MB (du of the whole venv, pip included) and the
largest entries of site-packages. Installs from the local checkout with the Python running this script.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def size_mb(path: Path) -> float:
    return round(sum(p.stat().st_size for p in path.rglob("*") if p.is_file() and not p.is_symlink()) / 2**20, 1)


def measure(extras: str, top: int) -> dict:
    with tempfile.TemporaryDirectory(prefix="spinefarm-size-") as tmp:
        venv = Path(tmp) / "venv"
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        pip = [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--disable-pip-version-check"]
        t0 = time.perf_counter()
        subprocess.run([*pip, f"{ROOT}[{extras}]"], check=True, capture_output=True)
        site = next((venv / "lib").glob("python3*/site-packages"))
        entries = sorted(((size_mb(p) if p.is_dir() else round(p.stat().st_size / 2**20, 1), p.name)
                          for p in site.iterdir() if not p.name.endswith(".dist-info")), reverse=True)
        return {"extras": extras, "venv_mb": size_mb(venv), "site_packages_mb": size_mb(site),
                "install_s": round(time.perf_counter() - t0, 1),
                "largest_mb": {name: mb for mb, name in entries[:top]}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--extras", nargs="+", default=["all", "all,parquet", "all,video"])
    ap.add_argument("--top", type=int, default=12, help="how many of the largest packages to list")
    args = ap.parse_args()
    print(json.dumps({"python": sys.version.split()[0], "sets": [measure(e, args.top) for e in args.extras]},
                     indent=1))


if __name__ == "__main__":
    main()
