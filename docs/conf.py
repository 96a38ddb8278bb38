"""Sphinx configuration of the fbmflow documentation site.

Build:  sphinx-build -W --keep-going -b html docs docs/_build/html   (``pip install -e ".[docs]"``)

The pages are Markdown (MyST); the API reference is rendered from the docstrings (autodoc,
NumPy style through napoleon), one page per module (autosummary), and every cross-reference in
a docstring must resolve (``nitpicky``): ``tests/test_docs.py`` builds the site with warnings as
errors.
"""
import fbmflow

project = "fbmflow"
author = "the fbmflow developers"
release = version = fbmflow.__version__
copyright = "fbmflow developers, BSD-3-Clause"

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary", "sphinx.ext.napoleon",
              "sphinx.ext.mathjax", "sphinx.ext.viewcode"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "generate_parameters.py"]
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]

autosummary_generate = True
autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": True,
                           "member-order": "bysource",
                           "ignore-module-all": True}  # each object on the page of the module defining it
autodoc_typehints = "description"
autodoc_class_signature = "separated"
napoleon_numpy_docstring = True
napoleon_google_docstring = False
napoleon_use_rtype = False
napoleon_use_param = False  # "name : (n, dim) float64" stays text: shapes and units are no types
napoleon_custom_sections = [("Attributes", "params_style")]  # the same for a dataclass's fields
nitpicky = True
#: references outside fbmflow (NumPy, SciPy, the standard library) stay unlinked: the site is built
#: offline, without intersphinx
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|scipy|sp|pathlib|collections|typing|numba|abc)(\..*)?"),
    (r"py:class", r"(optional|callable|array_like|.*\.ndarray|float|int|bool|str|dict|list|tuple)"),
    (r"py:class", r".*\._[A-Za-z]\w*")]  # a private class named in a type annotation has no page

html_theme = "furo"
html_title = f"fbmflow {release}"

#: the public names on the API's first page, by group (every name of ``fbmflow.__all__`` once;
#: tests/test_docs.py checks)
PUBLIC = [
    ("Running a simulation", ["Simulation", "StepReport", "resume", "InsufficientMemory"]),
    ("Parameter sections", ["FluidParams", "TimeParams", "SolverParams", "CouplingParams",
                            "FictitiousBoundaryParams", "ContactParams", "RepulsionParams", "from_dict",
                            "ParamError"]),
    ("Strategies, chosen by name in the sections", ["COUPLINGS", "FORCE_ESTIMATORS", "LINEAR_SOLVERS",
                                                    "TIME_SCHEMES"]),
    ("Particles and shapes", ["Particles", "Ball", "Ellipsoid", "Box", "Cylinder", "ImplicitShape",
                              "TriangulatedSurface"]),
    ("Meshes and flows without particles", ["StructuredMesh", "FlowSpace", "NavierStokesProblem", "Dirichlet",
                                            "NoSlip", "Slip", "DoNothing", "advance", "NewtonSettings",
                                            "ConvergenceError"]),
    ("Built-in scenes", ["SCENES", "get_scene", "load_scene", "run_scene"]),
]


def canonical(name: str) -> tuple[str, str]:
    """``(role, dotted path)`` of a public name where it is defined (its module's page)."""
    import importlib
    import inspect
    import pkgutil
    import re

    obj = getattr(fbmflow, name)
    if inspect.isclass(obj):
        return ("exc" if issubclass(obj, BaseException) else "class"), f"{obj.__module__}.{obj.__qualname__}"
    if inspect.isfunction(obj):
        return "func", f"{obj.__module__}.{obj.__qualname__}"
    package = importlib.import_module(fbmflow._API[name])
    modules = [package] + [importlib.import_module(m.name) for m in
                           pkgutil.walk_packages(getattr(package, "__path__", []), package.__name__ + ".")]
    for module in modules:
        try:
            source = inspect.getsource(module)
        except (OSError, TypeError):
            continue
        if re.search(rf"^{name}\b[^=\n]*=", source, re.M):
            return "data", f"{module.__name__}.{name}"
    raise LookupError(f"no module defines {name}")


def write_public(app) -> None:
    """docs/api/public.rst: the public names by group, each a link to its reference entry."""
    from pathlib import Path

    lines = []
    for title, names in PUBLIC:
        lines += [title, "-" * len(title), ""]
        for name in names:
            role, path = canonical(name)
            lines.append(f"- :py:{role}:`{name} <{path}>`")
        lines.append("")
    (Path(app.srcdir) / "api" / "public.rst").write_text("\n".join(lines))


_KEPT: dict = {}


def keep_attribute_text(app, what, name, obj, options, lines) -> None:
    """Napoleon reads an attribute's docstring ``"(n, dim) float64: the centres"`` as the type
    ``(n, dim) float64``; attributes, properties and data keep their text as written (saved here
    before napoleon, restored by :func:`restore_attribute_text` after it)."""
    if what in ("attribute", "property", "data"):
        _KEPT[name] = list(lines)


def restore_attribute_text(app, what, name, obj, options, lines) -> None:
    if name in _KEPT:
        lines[:] = _KEPT.pop(name)


def public_bases(app, name, obj, options, bases) -> None:
    """Show a class's public bases only (a private base has no page of its own)."""
    bases[:] = [b for b in bases if not b.__name__.startswith("_")]


def setup(app):
    app.connect("builder-inited", write_public)
    app.connect("autodoc-process-bases", public_bases)
    app.connect("autodoc-process-docstring", keep_attribute_text, priority=100)  # before napoleon (500)
    app.connect("autodoc-process-docstring", restore_attribute_text, priority=900)  # after it
