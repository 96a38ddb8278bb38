"""The example notebooks are current with their scripts and run (small size).

The ten Cate notebook is only compiled unless ``FBMFLOW_SLOW_EXAMPLES=1``: even its smallest run
(two steps of the 3D scene at level 0, 99 000 unknowns) takes about 8 minutes on the 2-core CI
machine (measured), which the 20-minute CI budget cannot carry."""
import ast
import json
import os
import sys
from pathlib import Path

import pytest

import fbmflow

EXAMPLES = Path(__file__).parents[1] / "examples"
sys.path.insert(0, str(EXAMPLES))
import make_notebooks  # noqa: E402


@pytest.mark.parametrize("name", make_notebooks.SCRIPTS)
def test_notebook_is_current_and_runs(name, tmp_path, monkeypatch):
    script = EXAMPLES / name
    notebook = script.with_suffix(".ipynb")
    assert notebook.read_text() == make_notebooks.notebook(script), \
        "notebook out of date: run python examples/make_notebooks.py"
    monkeypatch.setenv("FBMFLOW_EXAMPLE_SIZE", "small")
    monkeypatch.chdir(tmp_path)
    import matplotlib
    matplotlib.use("Agg")
    namespace: dict = {}
    code = [c["source"] for c in json.loads(notebook.read_text())["cells"] if c["cell_type"] == "code"]
    if name == "ten_cate.py" and not os.environ.get("FBMFLOW_SLOW_EXAMPLES"):
        for source in code:
            compile(source, name, "exec")
        return
    for source in code:
        exec(source, namespace)
    assert list(tmp_path.glob("*.png")), "the example saves its figure"


@pytest.mark.parametrize("name", make_notebooks.SCRIPTS)
def test_examples_use_only_the_public_api(name):
    """``import fbmflow`` and its public names (``fbmflow.__all__``), plus the reference data
    ``fbmflow.scenes.data``; nothing of the internals."""
    bad = []
    for node in ast.walk(ast.parse((EXAMPLES / name).read_text())):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("fbmflow"):
            if node.module == "fbmflow":
                bad += [a.name for a in node.names if a.name not in fbmflow.__all__]
            elif node.module != "fbmflow.scenes.data":
                bad.append(node.module)
        elif isinstance(node, ast.Import):
            bad += [a.name for a in node.names if a.name.startswith("fbmflow") and a.name != "fbmflow"]
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "fb":
            if node.attr not in fbmflow.__all__:
                bad.append(f"fb.{node.attr}")
    assert not bad, bad
