"""vshake: the virtual shake table (a nonlinear servo-hydraulic model of the UCSD-NEES LHPOST)
from Python.

Every function runs the same engine as the ``study`` command line, on all cores with the GIL
released, and raises :class:`VshakeError` (:class:`InputError` for bad input, naming the file,
key, column or row) with the command line's message.

- :func:`run`: a study (file, TOML text or dict) -> a ``pyarrow.Table``, as ``study run`` writes it;
- :func:`evaluate`: parameter sets (a dict of arrays, a DataFrame, or a 2-D array with names)
  against a study's excitations -> a DataFrame of metrics: SALib's ``Y = model(X)``;
- :func:`simulate`: one run -> a DataFrame of time histories (``.attrs["metrics"]``);
- :func:`compare`, :func:`diagnose`, :func:`fit`: a measured campaign -> an object holding the
  tables and the verdict, shown as HTML in a notebook;
- :func:`params`, :func:`effects`: the parameters (unit, default, range, source) and the effect
  library;
- :func:`plot_study`: the plots of ``study plot`` (Sobol' indices, metric against each parameter,
  failed runs) from a results table.

See docs/python.md for a walk-through.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Union

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from . import _native
from ._native import InputError, VshakeError

__version__: str = _native.__version__

__all__ = [
    "run",
    "evaluate",
    "simulate",
    "compare",
    "diagnose",
    "fit",
    "params",
    "effects",
    "plot_study",
    "Comparison",
    "Diagnosis",
    "Fit",
    "VshakeError",
    "InputError",
]

PathLike = Union[str, "os.PathLike[str]"]
StudyLike = Union[PathLike, Mapping[str, Any]]
# A model: a model file, its TOML text, or a dict ({"controller.g_d": 1.5}).
ModelLike = Union[PathLike, Mapping[str, Any], None]


def _is_path(obj: Any) -> bool:
    """A path, not TOML text: a PathLike, or a one-line string with no `=` or `[` (TOML text has
    a key = value or a [table])."""
    if isinstance(obj, os.PathLike):
        return True
    return isinstance(obj, str) and not any(c in obj for c in "\n=[")


def _file(path: PathLike, what: str) -> str:
    """The path of an existing file, else InputError naming it."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a folder, not a {what}")
    if not p.is_file():
        raise InputError(f"{p}: no such {what}")
    return str(p)


def _names(x: Union[None, str, Iterable[str]]) -> Optional[List[str]]:
    """A list of names from one name or several."""
    if x is None:
        return None
    return [x] if isinstance(x, str) else [str(n) for n in x]


def _threads(n: int) -> int:
    if not isinstance(n, (int, np.integer)) or n < 0:
        raise InputError(f"threads={n!r}: a whole number of worker threads, 0 for every core")
    return int(n)


def _toml(obj: Mapping[str, Any]) -> str:
    """TOML text of a dict (NumPy numbers and arrays become TOML numbers and arrays)."""

    def plain(x: Any) -> Any:
        if isinstance(x, Mapping):
            return {str(k): plain(v) for k, v in x.items()}
        if isinstance(x, (list, tuple, np.ndarray)):
            return [plain(v) for v in x]
        if isinstance(x, np.generic):
            return x.item()
        if isinstance(x, os.PathLike):
            return os.fspath(x)
        return x

    return _native.toml_of_json(json.dumps(plain(obj)))


def _study_args(study: StudyLike) -> Dict[str, Any]:
    """The native call's study arguments: a file's path, or TOML text read from the current folder."""
    if isinstance(study, Mapping):
        return {"toml": _toml(study), "base": os.getcwd()}
    if _is_path(study):
        return {"path": _file(study, "study file")}
    return {"toml": str(study), "base": os.getcwd()}


def _model_tables(model: Mapping[str, Any]) -> Dict[str, Any]:
    """``{"controller.g_d": 1.5}`` or ``{"controller": {"g_d": 1.5}}`` as [model.*] tables."""
    tables: Dict[str, Dict[str, Any]] = {}
    for key, value in model.items():
        if isinstance(value, Mapping):
            tables.setdefault(key, {}).update(value)
        elif "." in key:
            component, name = key.split(".", 1)
            tables.setdefault(component, {})[name] = value
        else:
            raise InputError(
                f"model: `{key}`: name a parameter as component.name (e.g. controller.g_d), "
                "or give a component's table"
            )
    return tables


def _model_path(model: ModelLike, scratch: Path) -> Optional[str]:
    """A model file for ``--model``: the path given, or a dict or a model file's text (such as
    ``Fit.model_toml``) written to a scratch file."""
    if model is None:
        return None
    if isinstance(model, Mapping) or (isinstance(model, str) and not _is_path(model)):
        path = scratch / "model.toml"
        text = _toml({"model": _model_tables(model)}) if isinstance(model, Mapping) else model
        path.write_text(text)
        return str(path)
    return _file(model, "model file")


class _Scratch:
    """A temporary folder removed on exit. An error that names a file written into it (a model
    given as a dict, a table given in memory) names the argument instead."""

    NAMES = {"model.toml": "model=", "results.parquet": "(the table given)"}

    def __enter__(self) -> Path:
        self.path = Path(tempfile.mkdtemp(prefix="vshake-"))
        return self.path

    def __exit__(self, kind: Any, error: Any, trace: Any) -> None:
        shutil.rmtree(self.path, ignore_errors=True)
        if isinstance(error, VshakeError) and error.args:
            message = str(error.args[0])
            for name, said in self.NAMES.items():
                message = message.replace(str(self.path / name), said)
            error.args = (message,) + tuple(error.args[1:])


def _read_table(path: Path) -> pa.Table:
    """The whole table in memory (its file may be removed afterwards), metadata included."""
    return pq.read_table(path, memory_map=False)


def run(
    study: StudyLike,
    out: Optional[PathLike] = None,
    model: ModelLike = None,
    threads: int = 0,
) -> pa.Table:
    """Runs a study as ``study run`` does and returns its results table.

    ``study`` is a study file's path, its TOML text, or a dict of the same tables (relative
    paths in text or a dict start at the current folder). ``out`` also writes the table there
    (a table vshake wrote is replaced; any other file is refused). ``model`` is a model file or
    a dict (``{"controller.g_d": 1.5}``). ``threads=0`` uses every core. The table carries the
    file's metadata (``table.schema.metadata``: ``vshake.study``, ``vshake.seed``, ...).
    """
    if out is not None and Path(out).is_dir():
        raise InputError(f"{out}: is a folder; name the results file (e.g. out='{Path(out) / 'results.parquet'}')")
    with _Scratch() as scratch:
        target = Path(out) if out is not None else scratch / "results.parquet"
        _native.run_study(
            str(target),
            model=_model_path(model, scratch),
            threads=_threads(threads),
            **_study_args(study),
        )
        return _read_table(target)


def _columns(params: Any, names: Optional[Sequence[str]]) -> List[tuple]:
    """(name, values) pairs of parameter sets given as a dict, a DataFrame or a 2-D array."""
    if isinstance(params, pd.DataFrame):
        items = [(str(c), params[c].to_numpy()) for c in params.columns]
    elif isinstance(params, Mapping):
        items = [(str(k), np.asarray(v)) for k, v in params.items()]
    else:
        x = np.asarray(params, dtype=float)
        if x.ndim != 2:
            raise InputError(f"params: a 2-D array (sets x parameters) is expected, not {x.ndim}-D")
        if names is None or len(names) != x.shape[1]:
            raise InputError(
                f"params: a {x.shape[0]} x {x.shape[1]} array needs names= with {x.shape[1]} "
                "parameter names (SALib's problem['names'])"
            )
        items = [(str(n), x[:, i]) for i, n in enumerate(names)]
    out = []
    for name, values in items:
        try:
            v = np.asarray(values, dtype=float).ravel()
        except (TypeError, ValueError):
            raise InputError(f"params: column `{name}` is not numeric") from None
        out.append((name, v.tolist()))
    return out


def _excitation_study(excitations: Any) -> Any:
    """A study (path, text or dict) from a study file, TOML text, a dict or a list of excitations
    (named ``excitation0``, ... where they have no name)."""
    if isinstance(excitations, Mapping) and "kind" in excitations:
        excitations = [dict(excitations, name=excitations.get("name", "excitation"))]
    if isinstance(excitations, (list, tuple)):
        named = [dict({"name": f"excitation{i}"}, **e) for i, e in enumerate(excitations)]
        return {"excitations": named}
    return excitations


def evaluate(
    params: Any,
    excitations: Any,
    metrics: Union[None, str, Sequence[str]] = None,
    names: Optional[Sequence[str]] = None,
    model: ModelLike = None,
    threads: int = 0,
    table: bool = False,
) -> Union[pd.DataFrame, pa.Table]:
    """Runs parameter sets through the model: SALib's ``Y = model(X)``, on every core.

    ``params``: a dict of arrays or a DataFrame, one row per set, columns named as ``params()``
    names them (``controller.g_d`` or the results' column name ``g_d``); or a 2-D array with
    ``names=`` (SALib's ``problem["names"]``); each parameter once. ``excitations``: a study file
    (its [[excitations]], [model.*], [solver], [spectrum], [responses] metrics and fixed
    [[variables]] are used; its other variables are replaced by the sets), a study's TOML text or
    dict, a list of excitation dicts (named ``excitation0``, ... where they have no name), or one.
    ``metrics`` chooses the metric columns (default: the study's). Returns one row per set and
    excitation, as ``study run`` writes them (``sample_id`` is the set's row; ``status`` says
    whether the run ended; a metric of a failed run is NaN); ``table=True`` returns the
    ``pyarrow.Table`` with its metadata instead.
    """
    columns = _columns(params, names)
    with _Scratch() as scratch:
        out = scratch / "evaluate.parquet"
        _native.evaluate(
            str(out),
            columns,
            metrics=_names(metrics),
            model=_model_path(model, scratch),
            threads=_threads(threads),
            **_study_args(_excitation_study(excitations)),
        )
        t = _read_table(out)
    return t if table else t.to_pandas()


def simulate(
    excitation: Union[Mapping[str, Any], PathLike],
    model: ModelLike = None,
    solver: Optional[Mapping[str, Any]] = None,
    check: bool = True,
) -> pd.DataFrame:
    """One run of the model, as ``study sim`` does: a DataFrame of the time history.

    ``excitation`` is an excitation dict (``{"kind": "sine", "freq_hz": 3.0, "amp_g": 1.73}``;
    docs/formats.md lists the kinds) or a run file (TOML with [excitation], [model.*],
    [solver]). ``model``: a model file or a dict of parameters. The DataFrame has one row per
    controller tick, one column per channel (``time_s``, ``ref_disp_m``, ``disp_m``,
    ``accel_mps2``, ...); ``.attrs["metrics"]`` holds the run's metrics (``h3``, ``thd_odd``,
    ``amp_ratio``, ...), ``.attrs["status"]`` says whether it ended. A run that fails (the
    stroke or pressure limit, divergence) raises :class:`VshakeError`; with ``check=False`` its
    history up to the failure is returned instead.
    """
    with _Scratch() as scratch:
        if isinstance(excitation, Mapping):
            doc: Dict[str, Any] = {"excitation": dict(excitation)}
            if solver:
                doc["solver"] = dict(solver)
            text, base = _toml(doc), os.getcwd()
        else:
            path = Path(_file(excitation, "run file"))
            if solver:
                raise InputError("solver=: give it in the run file's [solver] table")
            text, base = path.read_text(), str(path.parent)
        out = scratch / "history.parquet"
        status, metrics = _native.simulate(text, str(out), base=base, model=_model_path(model, scratch))
        df = _read_table(out).to_pandas()
    df.attrs["metrics"] = dict(metrics)
    df.attrs["status"] = status
    if check and status != "ok":
        raise VshakeError(f"the run {status} (simulate(..., check=False) returns its history)")
    return df


def _report_tables(folder: Path) -> Dict[str, pa.Table]:
    return {p.stem: _read_table(p) for p in sorted(folder.glob("*.parquet"))}


def _html_table(t: Optional[pa.Table], rows: int = 20) -> str:
    if t is None:
        return ""
    return t.slice(0, rows).to_pandas().to_html(index=False, float_format=lambda v: f"{v:.4g}")


class _Result:
    """A command's outcome: its printed report (``text``) and its tables (pyarrow)."""

    _title = "vshake"
    _main_table = "tests"

    def __init__(self, text: str, tables: Dict[str, pa.Table], report: Optional[Path]) -> None:
        self.text = text
        self.tables = tables
        self.report = report / "report.html" if report is not None else None

    def __repr__(self) -> str:
        return self.text

    def _repr_html_(self) -> str:
        import html

        return (
            f"<h4>{html.escape(self._title)}</h4>"
            + self._html_head()
            + _html_table(self.tables.get(self._main_table))
            + f"<details><summary>report</summary><pre>{html.escape(self.text)}</pre></details>"
        )

    def _html_head(self) -> str:
        return ""


class Comparison(_Result):
    """``study compare``: ``text`` (the printed comparison) and ``tables`` (tests, harmonics,
    bins, cycles, overlay, statemap, stateterms)."""

    _title = "model versus measurement"

    @property
    def tests(self) -> pd.DataFrame:
        """One row per test: amplitude ratio, phase, THD, errors."""
        return self.tables["tests"].to_pandas()


class Diagnosis(_Result):
    """``study diagnose``: the ``verdict``, ``text`` and ``tables`` (candidates, selection,
    tests, evidence, statemap, stateterms)."""

    _title = "diagnosis"
    _main_table = "candidates"

    @property
    def verdict(self) -> str:
        """The verdict line: ``most likely missing: NAME (family) with p = v, ...; ...``."""
        m = re.search(r"^\s*verdict: (.*)$", self.text, re.M)
        return m.group(1) if m else ""

    @property
    def candidates(self) -> pd.DataFrame:
        """One row per candidate effect, best first."""
        return self.tables["candidates"].to_pandas()

    def _html_head(self) -> str:
        import html

        return f"<p><b>verdict:</b> {html.escape(self.verdict)}</p>"


class Fit(_Result):
    """``study fit``: ``estimates`` (parameter, estimate, std_error), ``model_toml`` (the fitted
    model file's text, for ``model=``), ``model_path`` where it was written, and ``text``."""

    _title = "fit"
    _main_table = "estimates"

    def __init__(self, text: str, model_toml: str, model_path: Optional[Path]) -> None:
        self.model_toml = model_toml
        self.model_path = model_path
        head = model_toml.splitlines()[0] if model_toml else ""
        rows = re.findall(r"([A-Za-z_0-9]+\.[A-Za-z_0-9]+) = ([^ ,]+) ± ([^ ,]+)", head)
        est = pd.DataFrame(
            [(p, float(e), float(s)) for p, e, s in rows],
            columns=["parameter", "estimate", "std_error"],
        )
        super().__init__(text, {"estimates": pa.Table.from_pandas(est, preserve_index=False)}, None)

    @property
    def estimates(self) -> pd.DataFrame:
        return self.tables["estimates"].to_pandas()


def _campaign(campaign: PathLike) -> str:
    return _file(campaign, "campaign file")


def compare(
    campaign: PathLike,
    model: ModelLike = None,
    report: Optional[PathLike] = None,
    threads: int = 0,
) -> Comparison:
    """Compares the model with a measured campaign (``study compare``). ``report`` keeps the
    report (report.html and the Parquet tables) in that folder."""
    with _Scratch() as scratch:
        folder = Path(report) if report is not None else scratch / "report"
        text = _native.compare(
            _campaign(campaign), str(folder), model=_model_path(model, scratch), threads=_threads(threads)
        )
        return Comparison(text, _report_tables(folder), Path(report) if report else None)


def diagnose(
    campaign: PathLike,
    model: ModelLike = None,
    candidates: Union[None, str, Iterable[str]] = None,
    report: Optional[PathLike] = None,
    out: Optional[PathLike] = None,
    threads: int = 0,
) -> Diagnosis:
    """Says which effect is most likely missing (``study diagnose``). ``candidates`` limits the
    effects tried; ``out`` writes the named effects' fitted model; ``report`` keeps the report."""
    with _Scratch() as scratch:
        folder = Path(report) if report is not None else scratch / "report"
        text = _native.diagnose(
            _campaign(campaign),
            str(folder),
            model=_model_path(model, scratch),
            candidates=_names(candidates) or [],
            out=str(out) if out is not None else None,
            threads=_threads(threads),
        )
        return Diagnosis(text, _report_tables(folder), Path(report) if report else None)


def fit(
    campaign: PathLike,
    effects: Union[str, Sequence[str]] = (),
    free: Union[str, Sequence[str]] = (),
    model: ModelLike = None,
    out: Optional[PathLike] = None,
    max_iter: int = 200,
    threads: int = 0,
) -> Fit:
    """Adds effects and calibrates their parameters (and ``free`` ones) on a campaign
    (``study fit``). ``out`` keeps the fitted model file; ``Fit.model_toml`` has its text."""
    with _Scratch() as scratch:
        target = Path(out) if out is not None else scratch / "fitted.toml"
        text = _native.fit(
            _campaign(campaign),
            str(target),
            effects=_names(effects) or [],
            free=_names(free) or [],
            model=_model_path(model, scratch),
            max_iter=max_iter,
            threads=_threads(threads),
        )
        return Fit(text, target.read_text(), Path(out) if out is not None else None)


def params(component: Optional[str] = None) -> pd.DataFrame:
    """Every parameter of the model and the effect library, as ``study params`` lists them:
    path, component, name, column, unit, default, low, high, range, source, meaning."""
    cols = ["parameter", "component", "name", "column", "unit", "default", "low", "high",
            "range", "source", "meaning"]
    df = pd.DataFrame(_native.params(), columns=cols)
    if component is not None:
        if component not in set(df["component"]):
            known = ", ".join(dict.fromkeys(df["component"]))
            raise InputError(f"unknown component `{component}`; expected one of: {known}")
        df = df[df["component"] == component].reset_index(drop=True)
    return df


def effects() -> pd.DataFrame:
    """The effect library: name, family, the parameters a diagnosis frees, what it adds."""
    return pd.DataFrame(_native.effects(), columns=["effect", "family", "frees", "adds"])


def plot_study(
    results: Union[PathLike, pa.Table],
    out: PathLike,
    metrics: Union[None, str, Sequence[str]] = None,
    bootstrap: int = 200,
) -> Path:
    """Draws a study's plots as ``study plot`` does (SVG files and index.html in ``out``):
    Sobol' indices with their intervals (a Saltelli design), each metric against each varied
    parameter, and the failed runs in parameter space. ``bootstrap``: resamples for the indices'
    95 % intervals. A folder holding other files is refused. Returns the index.html path."""
    with _Scratch() as scratch:
        if isinstance(results, pa.Table):
            path = scratch / "results.parquet"
            pq.write_table(results, path)
        else:
            path = Path(_file(results, "results file"))
        _native.plot_study(str(path), str(out), metrics=_names(metrics), bootstrap=bootstrap)
    return Path(out) / "index.html"
