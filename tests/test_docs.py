"""The generated parameter reference is up to date with the parameter dataclasses."""
import importlib.util
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_parameters_md_is_current():
    spec = importlib.util.spec_from_file_location("gen", DOCS / "generate_parameters.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    assert (DOCS / "parameters.md").read_text() == gen.render(), "docs/parameters.md is stale: run python docs/generate_parameters.py"


def test_tutorial_python_example_runs():
    """The tutorial's Python example, cut to three steps."""
    import re
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "tutorial.md").read_text()
    code = re.findall(r"```python\n(.*?)```", text, re.S)[0]
    assert "range(100)" in code
    namespace: dict = {}
    exec(code.replace("range(100)", "range(3)"), namespace)
    assert namespace["report"].step == 3
