"""Imports point down only (docs/design.md, "Layers")."""
import ast
from pathlib import Path

import fbmflow

ROOT = Path(fbmflow.__file__).parent
FORBIDDEN = {
    "mesh": {"fem", "solvers", "flow", "particles", "contact", "coupling", "scenes", "io", "cli", "simulation"},
    "fem": {"solvers", "flow", "particles", "contact", "coupling", "scenes", "io", "cli", "simulation"},
    "solvers": {"flow", "particles", "contact", "coupling", "scenes", "io", "cli", "simulation"},
    "flow": {"particles", "contact", "coupling", "scenes", "io", "cli", "simulation"},
    "particles": {"mesh", "fem", "solvers", "flow", "contact", "coupling", "scenes", "io", "cli", "simulation"},
    "contact": {"mesh", "fem", "solvers", "flow", "coupling", "scenes", "io", "cli", "simulation"},
}


def _imported_subpackages(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    rel = path.relative_to(ROOT).parts
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


def test_imports_point_down():
    bad = []
    for package, forbidden in FORBIDDEN.items():
        for path in (ROOT / package).rglob("*.py") if (ROOT / package).is_dir() else []:
            hits = _imported_subpackages(path) & forbidden
            if hits:
                bad.append(f"{path.relative_to(ROOT)} imports {sorted(hits)}")
    assert not bad, bad


def _imports_numba(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "numba" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and not node.level and (node.module or "").split(".")[0] == "numba":
            return True
    return False


def test_only_jit_module_imports_numba():
    users = [p.relative_to(ROOT) for p in ROOT.rglob("*.py") if p.name != "_jit.py" and _imports_numba(p)]
    assert not users, users
    assert _imports_numba(ROOT / "_jit.py")
