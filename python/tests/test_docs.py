"""docs/python.md's `python` blocks, run in order as a notebook's cells, each cell's printed output
compared with the `text` block quoted after it, by tests/check_docs.py's rules (to the character,
`...` elisions)."""

import contextlib
import difflib
import importlib.util
import io
import os
import re


def check_docs(root):
    """tests/check_docs.py as a module: the shell pages' comparison (`trim`, `align`)."""
    spec = importlib.util.spec_from_file_location("check_docs", root / "tests" / "check_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def cells(text):
    """(code, quoted output or None) for each `python` block: the output is the `text` block
    directly after it (blank lines between), as the page's convention has it."""
    pattern = re.compile(r"^```python\n(.*?)^```\n(?:\s*\n)*(?:```text\n(.*?)^```)?", re.S | re.M)
    return [(m.group(1), m.group(2)) for m in pattern.finditer(text)]


def test_every_python_block_of_docs_python_md_runs_and_prints_what_it_shows(
    root, tmp_path, monkeypatch
):
    docs = check_docs(root)
    blocks = cells((root / "docs" / "python.md").read_text())
    assert len(blocks) >= 7
    assert sum(out is not None for _, out in blocks) >= 7, "cells with a quoted output"
    # The page runs from the repository root; its outputs go to a scratch copy of it.
    os.symlink(root / "studies", tmp_path / "studies")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    differences = []
    for i, (block, quoted) in enumerate(blocks):
        printed = io.StringIO()
        try:
            with contextlib.redirect_stdout(printed):
                exec(compile(block, f"docs/python.md block {i + 1}", "exec"), namespace)
        except Exception as e:
            raise AssertionError(f"docs/python.md, python block {i + 1} raised {e!r}:\n{block}") from e
        if quoted is None:
            continue
        expected = docs.trim(quoted.splitlines())
        actual = docs.trim(printed.getvalue().splitlines())
        cost, rendered = docs.align(expected, actual)
        if cost:
            diff = "\n".join(
                difflib.unified_diff(expected, rendered, "quoted", "printed", lineterm="")
            )
            differences.append(f"docs/python.md, python block {i + 1}:\n{diff}")
    assert not differences, "\n\n".join(differences)
    assert namespace["d"].verdict.startswith("most likely missing: seal_friction")
    assert abs(namespace["h"].attrs["metrics"]["h3_ratio"] / 0.0309 - 1) < 0.02
