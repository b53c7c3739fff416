"""docs/api.md's example runs as written: it flies its custom plan for several seeds and measures it."""
from __future__ import annotations

import re
from helpers.paths import ROOT

DOC = ROOT / "docs" / "api.md"


def test_the_example_runs(capsys, monkeypatch, tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert blocks, "docs/api.md has no python block"
    monkeypatch.chdir(tmp_path)
    for k, code in enumerate(blocks):
        exec(compile(code, f"{DOC}:block{k + 1}", "exec"), {"__name__": "__api_doc__"})
    out = capsys.readouterr().out
    seeds = re.findall(r"^seed (\d+): (.*?); rise ([\d.]+) s", out, re.M)
    assert len(seeds) >= 3
    assert all(0.0 < float(rise) < 0.5 for _, _, rise in seeds)      # a roll step answered in tenths of a second


def test_every_documented_call_exists():
    import importlib
    for module, name in re.findall(r"`(flightctl(?:\.\w+)+)\.(\w+)\(", DOC.read_text()):
        assert hasattr(importlib.import_module(module), name), f"{module}.{name}"
