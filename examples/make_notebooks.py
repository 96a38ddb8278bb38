"""Write the Jupyter notebooks ``examples/*.ipynb`` from the percent-format scripts beside them
(``# %%`` starts a code cell, ``# %% [markdown]`` a markdown cell). The scripts are the source;
``tests/test_examples.py`` checks that the notebooks are current and runs them at a small size.

Run:  python examples/make_notebooks.py
"""
from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).parent
SCRIPTS = ["settling_ball.py", "glowinski_free_fall.py", "ten_cate.py", "dkt.py", "fluidized_bed.py"]


def cells(source: str) -> list[dict]:
    out = []
    for chunk in source.split("# %%")[1:]:
        head, _, body = chunk.partition("\n")
        if head.strip() == "[markdown]":
            text = [line[2:] if line.startswith("# ") else line.lstrip("#")
                    for line in body.strip("\n").split("\n")]
            out.append({"cell_type": "markdown", "metadata": {}, "source": "\n".join(text)})
        else:
            out.append({"cell_type": "code", "metadata": {}, "execution_count": None, "outputs": [],
                        "source": body.strip("\n")})
    return out


def notebook(script: Path) -> str:
    nb = {"cells": cells(script.read_text()), "nbformat": 4, "nbformat_minor": 5,
          "metadata": {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"},
                       "language_info": {"name": "python"}}}
    return json.dumps(nb, indent=1) + "\n"


def main():
    for name in SCRIPTS:
        script = HERE / name
        script.with_suffix(".ipynb").write_text(notebook(script))
        print("wrote", script.with_suffix(".ipynb"))


if __name__ == "__main__":
    main()
