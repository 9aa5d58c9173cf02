#!/usr/bin/env python3
"""Installs the Python packages the tests open results with into .pydeps/ (in the repository).

    python3 tests/pydeps.py                 # pyarrow and duckdb (what `cargo test` needs)
    python3 tests/pydeps.py numpy pillow    # others CI uses

Works on a stock Debian or Ubuntu Python (PEP 668, "externally-managed-environment"): pip installs
with --target, which writes into a folder of ours and leaves the system's packages alone. Where the
system Python has no pip (Debian's python3 without python3-pip), pip's own wheel is fetched from
PyPI and run from the wheel. The tests put .pydeps/ on PYTHONPATH themselves; for the other scripts
use `PYTHONPATH=$PWD/.pydeps`. Packages already importable are not installed again.
"""
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import urllib.parse
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = os.path.join(ROOT, ".pydeps")
# The import name of a package where it differs from its name on PyPI.
IMPORT_NAME = {"pillow": "PIL", "nvidia-cuda-nvrtc": None}


def missing(packages):
    sys.path.insert(0, TARGET)
    out = []
    for p in packages:
        name = IMPORT_NAME.get(p, p.replace("-", "_"))
        if name is None or importlib.util.find_spec(name) is None:
            out.append(p)
    return out


def pip_command():
    """`python3 -m pip`, or pip run from its wheel fetched from PyPI where there is none."""
    have_pip = importlib.util.find_spec("pip") is not None
    if have_pip and not os.environ.get("VSHAKE_PYDEPS_BOOTSTRAP"):
        return [sys.executable, "-m", "pip"]
    index = "https://pypi.org/pypi/pip/json"
    with urllib.request.urlopen(index, timeout=60) as r:
        info = json.load(r)
    wheel = next(u for u in info["urls"] if u["filename"].endswith(".whl"))
    path = os.path.join(tempfile.mkdtemp(prefix="vshake-pip-"), wheel["filename"])
    # A mirror may give the file's address relative to the index's.
    urllib.request.urlretrieve(urllib.parse.urljoin(index, wheel["url"]), path)
    print(f"pydeps: no pip in {sys.executable}; running {wheel['filename']} from PyPI")
    return [sys.executable, os.path.join(path, "pip")]


def main(argv):
    packages = argv or ["pyarrow", "duckdb"]
    todo = missing(packages)
    if not todo:
        print(f"pydeps: {', '.join(packages)} already importable")
        return 0
    cmd = pip_command() + ["install", "-q", "--disable-pip-version-check", "--target", TARGET]
    # Root in a container or CI: pip's warning about it does not apply to a --target folder.
    env = dict(os.environ, PIP_ROOT_USER_ACTION="ignore")
    result = subprocess.run(cmd + todo, env=env)
    if result.returncode != 0:
        print(f"pydeps: could not install {', '.join(todo)} into {TARGET}", file=sys.stderr)
        return result.returncode
    print(f"pydeps: {', '.join(todo)} installed into {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
