"""Imports point down only (docs/design.md, "Layers"), for every package and top-level module."""
import ast
from pathlib import Path

import pytest

import fbmflow

ROOT = Path(fbmflow.__file__).parent
#: the layers from the top down: each may import only those below it
LAYERS = ["cli", "scenes", "simulation", "adaptive", "run", "io", "coupling", "contact", "particles", "flow",
          "gpu", "solvers", "parallel", "fem", "mesh", "params", "config", "interrupt", "kept", "cores",
          "_jit"]
#: packages that must not see some lower ones: particles and contact know nothing of meshes
#: (they work on positions, velocities and shapes), and contact imports particles only
UNSEEN = {"particles": {"flow", "solvers", "fem", "mesh"},
          "contact": {"io", "coupling", "flow", "solvers", "fem", "mesh"}}
#: names any module may take from the package root (it does no work at import time)
ROOT_NAMES = {"__version__"}


def _imported_subpackages(path: Path, root: Path = ROOT) -> set[str]:
    """The fbmflow packages, top-level modules and root names that the module at ``path`` (in the
    package tree ``root``) imports."""
    tree = ast.parse(path.read_text())
    rel = path.relative_to(root).parts
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(rel[:-1])[: len(rel) - node.level]
                target = base + (node.module.split(".") if node.module else [])
                if target:
                    found.add(target[0].removesuffix(".py"))
                else:
                    found.update(a.name for a in node.names)
            elif node.module and node.module.startswith("fbmflow."):
                found.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("fbmflow."):
                    found.add(a.name.split(".")[1])
    return found


def _layer_of(path: Path) -> str:
    return path.relative_to(ROOT).parts[0].removesuffix(".py")


def test_every_package_has_a_layer():
    units = {_layer_of(p) for p in ROOT.rglob("*.py")} - {"__init__"}
    assert units == set(LAYERS), \
        f"place {sorted(units - set(LAYERS))} in LAYERS; drop {sorted(set(LAYERS) - units)}"


@pytest.mark.parametrize("layer", LAYERS)
def test_imports_point_down(layer):
    below = set(LAYERS[LAYERS.index(layer) + 1:]) - UNSEEN.get(layer, set())
    bad = []
    for path in sorted(p for p in ROOT.rglob("*.py") if _layer_of(p) == layer):
        hits = _imported_subpackages(path) - below - {layer} - ROOT_NAMES
        if hits:
            bad.append(f"{path.relative_to(ROOT)} imports {sorted(hits)}")
    assert not bad, bad


def test_the_checker_sees_relative_and_absolute_imports(tmp_path):
    """Relative (``from ..scenes``, ``from . import``) and absolute imports are all seen."""
    fake = tmp_path / "fbmflow"
    (fake / "mesh").mkdir(parents=True)
    bad = fake / "mesh" / "bad.py"
    bad.write_text("from ..scenes import SCENES\nfrom fbmflow.flow import NoSlip\nfrom . import structured\n"
                   "import fbmflow.io.fields\nfrom .. import __version__\n")
    assert _imported_subpackages(bad, fake) == {"scenes", "flow", "mesh", "io", "__version__"}


def _imports_numba(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "numba" for a in node.names):
            return True
        absolute = isinstance(node, ast.ImportFrom) and not node.level
        if absolute and (node.module or "").split(".")[0] == "numba":
            return True
    return False


def test_only_jit_module_imports_numba():
    users = [p.relative_to(ROOT) for p in ROOT.rglob("*.py") if p.name != "_jit.py" and _imports_numba(p)]
    assert not users, users
    assert _imports_numba(ROOT / "_jit.py")
