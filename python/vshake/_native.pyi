"""Type stubs of vshake._native, the compiled layer under the vshake package (python/src/lib.rs).
Use the functions of `vshake` itself; these take paths and TOML text and write files."""

from os import PathLike
from pathlib import Path
from typing import List, Optional, Tuple, Union

_Path = Union[str, "PathLike[str]"]

__version__: str

class VshakeError(Exception):
    """A vshake error: a run that failed, or the system (exit code 1 of `study`)."""

class InputError(VshakeError):
    """Bad input: the message names the file, key, column or row (exit code 2 of `study`)."""

def run_study(
    out: _Path,
    path: Optional[_Path] = None,
    toml: Optional[str] = None,
    base: _Path = ".",
    model: Optional[_Path] = None,
    threads: int = 0,
) -> str: ...
def evaluate(
    out: _Path,
    columns: List[Tuple[str, List[float]]],
    path: Optional[_Path] = None,
    toml: Optional[str] = None,
    base: _Path = ".",
    metrics: Optional[List[str]] = None,
    model: Optional[_Path] = None,
    threads: int = 0,
) -> str: ...
def simulate(
    toml: str, out: _Path, base: _Path = ".", model: Optional[_Path] = None
) -> Tuple[str, List[Tuple[str, float]]]: ...
def compare(
    campaign: _Path, report: _Path, model: Optional[_Path] = None, threads: int = 0
) -> str: ...
def diagnose(
    campaign: _Path,
    report: _Path,
    model: Optional[_Path] = None,
    candidates: List[str] = ...,
    out: Optional[_Path] = None,
    threads: int = 0,
) -> str: ...
def fit(
    campaign: _Path,
    out: _Path,
    effects: List[str] = ...,
    free: List[str] = ...,
    model: Optional[_Path] = None,
    max_iter: int = 200,
    threads: int = 0,
) -> str: ...
def plot_study(
    results: _Path, out: _Path, metrics: Optional[List[str]] = None, bootstrap: int = 200
) -> Path: ...
def params() -> List[Tuple[str, str, str, str, str, float, float, float, str, str, str]]: ...
def effects() -> List[Tuple[str, str, List[str], str]]: ...
def toml_of_json(json: str) -> str: ...
