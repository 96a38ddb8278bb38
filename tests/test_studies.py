"""The studies in ``benchmarks/studies/``: each imports against today's fbmflow, has its header
(question, answer, when and where measured, the command) citing a page of docs/validation/ that
exists (and a section of it, where it names one), and a command line that the shared entry point
makes from it."""
import re
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
from fbmbench import study  # noqa: E402

VALIDATION = BENCHMARKS.parent / "docs" / "validation"


def test_benchmarks_holds_the_suite_and_nothing_else():
    """At most ten Python files directly in benchmarks/: the pytest suite; studies live in
    benchmarks/studies/, shared code in benchmarks/fbmbench/."""
    files = sorted(p.name for p in BENCHMARKS.glob("*.py"))
    assert len(files) <= 10 and all(f == "conftest.py" or f.startswith("test_") for f in files), files


@pytest.mark.parametrize("name", study.names())
def test_every_study_imports_and_says_what_it_answers(name):
    module = study.load(name)
    fields = study.header(module)
    cited = re.search(r'docs/validation/([a-z0-9\-]+)\.md(?:, "([^"]+)")?', fields["Measured"])
    assert cited and (VALIDATION / f"{cited.group(1)}.md").is_file(), (name, fields["Measured"])
    if cited.group(2):
        headings = re.findall(r"^#+ (.+)$", (VALIDATION / f"{cited.group(1)}.md").read_text(), re.M)
        assert " ".join(cited.group(2).split()) in headings, (name, cited.group(2))
    assert re.search(r"\d{4}-\d{2}-\d{2}, commit [0-9a-f]{7}", fields["Measured"]), fields["Measured"]
    assert fields["Run"].startswith(f"python -m fbmbench {name}")
    parser = study.parser(name, module)
    assert study.arguments(parser, fields["Run"].split()[4:]) is not None  # the header's command parses


def test_no_study_reaches_into_fbmflow_s_private_names():
    """Studies use public names and hooks (e.g. ``NavierStokesProblem.on_linear_solve``), never
    patch or read a private attribute of fbmflow."""
    paths = sorted((BENCHMARKS / "studies").glob("*.py")) + sorted((BENCHMARKS / "fbmbench").glob("*.py"))
    for path in paths:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            code = line.split("#")[0]
            for match in re.finditer(r"(\w+)\.(_[a-z]\w*)", code):
                assert match.group(1) in ("self", "cls"), f"{path.name}:{number}: {line.strip()}"
