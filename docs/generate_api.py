"""Write docs/api.md: every public name of ``fbmflow`` (``fbmflow.__all__``) with its signature and
docstring, from the code. ``tests/test_docs.py`` checks that the page is current.

Run:  python docs/generate_api.py
"""
import dataclasses
import inspect
import re
from pathlib import Path

import fbmflow
from fbmflow.config import Section, describe

#: the order of the page: (heading, introduction, names); every name of fbmflow.__all__ once
GROUPS = [
    ("Running a simulation",
     "A `Simulation` is made from a mesh, the particles and the parameter sections below; `run()` "
     "steps it to `time.t_end`, `step()` takes one step and returns a `StepReport`.",
     ["Simulation", "StepReport", "InsufficientMemory"]),
    ("Parameter sections",
     "Frozen dataclasses: every value is checked when a section is made (`ParamError` names the field "
     "and what is allowed). `from_dict` builds one from a nested dictionary, as a TOML scene file does.",
     ["FluidParams", "TimeParams", "SolverParams", "CouplingParams", "FictitiousBoundaryParams",
      "ContactParams", "RepulsionParams", "from_dict", "ParamError"]),
    ("Strategies",
     "Registries of interchangeable schemes, chosen by name in the parameter sections.",
     ["COUPLINGS", "FORCE_ESTIMATORS", "LINEAR_SOLVERS", "TIME_SCHEMES"]),
    ("Particles and shapes", "", ["Particles", "Ball", "Ellipsoid", "Box", "Cylinder", "ImplicitShape",
                                  "TriangulatedSurface"]),
    ("Meshes and flows without particles", "",
     ["StructuredMesh", "FlowSpace", "NavierStokesProblem", "Dirichlet", "NoSlip", "Slip", "DoNothing",
      "advance", "NewtonSettings", "ConvergenceError"]),
    ("Built-in scenes",
     "The scene library behind the command line, the benchmarks and the examples; its reference data "
     "(digitised curves and tables) are the modules `fbmflow.scenes.data.koblitz2017`, "
     "`fbmflow.scenes.data.tencate2002` and `fbmflow.scenes.data.ghia1982`.",
     ["SCENES", "get_scene", "load_scene", "run_scene", "resume"]),
]


def _default(value) -> str:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return f"{type(value).__name__}()" if value == type(value)() else repr(value)
    return repr(value)


def _signature(obj) -> str:
    """``name(parameters)`` with the defaults written short (a default section as ``Class()``)."""
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return ""
    parts, star = [], False
    for p in sig.parameters.values():
        if p.kind is p.KEYWORD_ONLY and not star:
            parts.append("*")
            star = True
        if p.kind is p.VAR_POSITIONAL:
            parts.append(f"*{p.name}")
            star = True
        elif p.kind is p.VAR_KEYWORD:
            parts.append(f"**{p.name}")
        else:
            parts.append(p.name if p.default is p.empty else f"{p.name}={_default(p.default)}")
    return f"{obj.__name__}({', '.join(parts)})"


def _markdown(doc: str) -> str:
    """A NumPy-style docstring as Markdown: Sphinx roles as code, section titles in bold, the
    entries of Parameters / Returns / Raises / Attributes as a list (their indented descriptions
    joined to them); other indented blocks (formulas) stay code blocks."""
    def role(match):  # :class:`~a.b.C` -> `C`, :func:`a.b` -> `a.b`
        return f"`{match.group(2).split('.')[-1] if match.group(1) else match.group(2)}`"

    doc = re.sub(r":[a-z]+:`(~?)([^`]+)`", role, doc)
    lines, out, listing, described = doc.split("\n"), [], False, False
    for i, line in enumerate(lines):
        if set(line.strip()) == {"-"} and i > 0 and lines[i - 1].strip():
            continue  # the underline of a section title (written below)
        if i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"} and line.strip():
            listing = line.strip() in ("Parameters", "Returns", "Raises", "Attributes", "Yields")
            out += [f"**{line.strip()}**", ""]
        elif listing and line and not line.startswith(" "):
            name, _, kind = line.partition(" : ")
            out.append(f"- `{name}`" + (f" ({kind})" if kind else ""))
            described = False
        elif listing and line.startswith(" "):
            out[-1] += (" " if described else ": ") + line.strip()
            described = True
        else:
            out.append(line)
    return "\n".join(out)


def _doc(obj) -> list[str]:
    doc = inspect.getdoc(obj) or ""
    return [_markdown(doc), ""] if doc else []


#: packages whose names the page gives by signature and summary only (their own docstrings say more)
SUMMARY_ONLY = ("fbmflow.mesh", "fbmflow.fem", "fbmflow.flow", "fbmflow.solvers")


def _members(cls) -> list[str]:
    """The public methods and properties a class defines itself, with their first docstring line."""
    lines = ["**Members**", ""]
    for name, member in cls.__dict__.items():
        if name.startswith("_") or not (callable(member) or isinstance(member, property)):
            continue
        if isinstance(member, (staticmethod, classmethod)):
            member = member.__func__
        first = _markdown((inspect.getdoc(member) or "").split("\n\n")[0]).replace("\n", " ")
        head = name if isinstance(member, property) else _signature(member).replace("self, ", "")
        head = f"- `{head.replace('(self)', '()')}`"
        lines.append(f"{head}: {first}" if first else head)
    return lines + [""] if len(lines) > 2 else []


def _entry(name: str) -> list[str]:
    obj = getattr(fbmflow, name)
    lines = [f"### `{name}`", ""]
    if isinstance(obj, dict):
        lines += [f"A registry: {', '.join(f'`{k}`' for k in obj)}.", ""]
        for key, value in obj.items():
            first = _markdown((inspect.getdoc(value) or "").split("\n\n")[0]).replace("\n", " ") \
                if inspect.isclass(value) else ""
            lines.append(f"- `{key}`: {first}" if first else f"- `{key}`")
        return lines + [""]
    if inspect.isclass(obj) and issubclass(obj, Section):
        lines += _doc(obj)
        lines += ["| field | default | unit | meaning |", "|---|---|---|---|"]
        lines += [f"| `{k}` | `{d}` | {u} | {doc} |" for k, d, u, doc in describe(obj)]
        return lines + [""] + _members(obj)
    signature = _signature(obj)
    if signature:
        lines += [f"`fbmflow.{signature}`", ""]
    if obj.__module__.startswith(SUMMARY_ONLY):
        summary = (inspect.getdoc(obj) or "").split("\n\n")[0]
        where = f"{obj.__module__}.{obj.__name__}"
        return lines + [_markdown(summary), "", f"(More in the docstring of `{where}`.)", ""]
    lines += _doc(obj)
    if inspect.isclass(obj) and not issubclass(obj, BaseException):
        lines += _members(obj)
    return lines


def render() -> str:
    """The Markdown text of docs/api.md."""
    listed = [n for _, _, names in GROUPS for n in names]
    public = [n for n in fbmflow.__all__ if n != "__version__"]
    missing, extra = set(public) - set(listed), set(listed) - set(public)
    if missing or extra:
        raise ValueError(f"docs/generate_api.py GROUPS out of step with fbmflow.__all__: add "
                         f"{sorted(missing)}, drop {sorted(extra)}")
    lines = ["# Python API", "",
             "Generated by `python docs/generate_api.py` from the docstrings of the names in "
             "`fbmflow.__all__` (import them as `import fbmflow as fb; fb.Simulation`). The scene "
             "parameters are in [parameters.md](parameters.md), a walk-through in "
             "[tutorial.md](tutorial.md).",
             ""]
    for heading, intro, names in GROUPS:
        lines += [f"## {heading}", ""] + ([intro, ""] if intro else [])
        for name in names:
            lines += _entry(name)
    return "\n".join(lines).rstrip("\n") + "\n"


def main() -> None:
    (Path(__file__).parent / "api.md").write_text(render())


if __name__ == "__main__":
    main()
