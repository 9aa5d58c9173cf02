"""Shared fixtures: the repository root and the `study` binary the package is compared with."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def study_bin() -> Path:
    """The command-line binary (VSHAKE_STUDY, else target/release/study of this checkout)."""
    path = Path(os.environ.get("VSHAKE_STUDY", ROOT / "target" / "release" / "study"))
    if not path.is_file():
        pytest.fail(f"{path}: no study binary; build it first: cargo build --release")
    return path


@pytest.fixture(scope="session")
def gains_sweep(study_bin, tmp_path_factory) -> Path:
    """studies/gains_sweep.toml run by the binary (8 192 samples x 2 excitations)."""
    out = tmp_path_factory.mktemp("binary") / "gains_sweep.parquet"
    subprocess.run(
        [str(study_bin), "run", str(ROOT / "studies/gains_sweep.toml"), "--out", str(out), "-q"],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    return out
