"""docs/python.md's `python` blocks, run in order as a notebook's cells."""

import os
import re


def test_every_python_block_of_docs_python_md_runs(root, tmp_path, monkeypatch):
    text = (root / "docs" / "python.md").read_text()
    blocks = re.findall(r"^```python\n(.*?)^```", text, re.S | re.M)
    assert len(blocks) >= 7
    # The page runs from the repository root; its outputs go to a scratch copy of it.
    os.symlink(root / "studies", tmp_path / "studies")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for i, block in enumerate(blocks):
        try:
            exec(compile(block, f"docs/python.md block {i + 1}", "exec"), namespace)
        except Exception as e:
            raise AssertionError(f"docs/python.md, python block {i + 1} raised {e!r}:\n{block}") from e
    assert namespace["d"].verdict.startswith("most likely missing: seal_friction")
    assert abs(namespace["h"].attrs["metrics"]["h3_ratio"] / 0.0309 - 1) < 0.02
