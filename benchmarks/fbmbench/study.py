"""The studies' one entry point: ``python -m fbmbench STUDY [--option value ...]``.

A study is a module in ``benchmarks/studies/`` (one question the project asked of the code, and
the run that answered it). Its docstring opens with a title line and a header::

    Question: what the study asks.
    Answer: what it found, with the figures.
    Measured: YYYY-MM-DD, commit abcdef0; quoted in docs/validation/PAGE.md, "Section heading".
    Run: python -m fbmbench NAME --option value

and its ``run(*, option=default, ...)`` takes keyword-only options whose annotations give their
command-line form: ``int``, ``float``, ``str`` (``Literal[...]`` for a choice), ``bool`` (a flag,
``--no-option`` to turn a default True off), ``list[int]``, ``list[float]`` or ``list[str]``
(several values), and ``Path``; an option without a default is positional. The docstring of
``run`` lists them in a NumPy "Parameters" section, which gives each its help text.
``python -m fbmbench`` alone lists the studies with their questions.

Run from the ``benchmarks`` folder, or with it on ``PYTHONPATH``.
"""
from __future__ import annotations

import argparse
import importlib
import inspect
import re
import sys
import typing
from pathlib import Path

STUDIES = Path(__file__).resolve().parents[1] / "studies"
#: the header fields every study's docstring has, in this order
HEADER = ("Question:", "Answer:", "Measured:", "Run:")


def names() -> list[str]:
    """The studies, by module name (sorted)."""
    return sorted(p.stem for p in STUDIES.glob("*.py") if p.stem != "__init__")


def load(name: str):
    """The study module ``name``; SystemExit listing the studies when there is none."""
    if name not in names():
        raise SystemExit(f"fbmbench: no study {name!r}; studies: {', '.join(names())}")
    root = str(STUDIES.parent)
    if root not in sys.path:
        sys.path.insert(0, root)
    return importlib.import_module(f"studies.{name}")


def header(module) -> dict[str, str]:
    """The header fields of a study's docstring, ``{"Question": ..., ...}``; ValueError naming a
    missing one."""
    doc = inspect.getdoc(module) or ""
    fields = {}
    for key in HEADER:
        match = re.search(rf"^{key}\s*(.+?)(?=^\S+:\s|^\s*$|\Z)", doc, re.M | re.S)
        if match is None:
            raise ValueError(f"{module.__name__}: the docstring lacks its '{key}' line")
        fields[key[:-1]] = " ".join(match.group(1).split())
    return fields


def _helps(function) -> dict[str, str]:
    """Help texts of a function's options from its docstring's NumPy "Parameters" section."""
    doc = inspect.getdoc(function) or ""
    section = re.search(r"Parameters\n-+\n(.*?)(?:\n\n[A-Z][a-z]+\n-+\n|\Z)", doc, re.S)
    helps: dict[str, str] = {}
    if section is None:
        return helps
    name = None
    for line in section.group(1).splitlines():
        match = re.match(r"^(\w+)\s*:", line)
        if match:
            name = match.group(1)
            helps[name] = line.split(":", 1)[1].strip()
        elif name is not None and line.strip():
            helps[name] = (helps[name] + " " + line.strip()).strip()
    return helps


def parser(name: str, module) -> argparse.ArgumentParser:
    """The command line of study ``name``, made from its ``run``'s signature."""
    run = module.run
    doc = (inspect.getdoc(module) or name).splitlines()[0]
    ap = argparse.ArgumentParser(prog=f"python -m fbmbench {name}", description=doc)
    hints = typing.get_type_hints(run)
    helps = _helps(run)
    lists: dict = {}  # list options and their defaults, filled in after parsing
    for pname, param in inspect.signature(run).parameters.items():
        kind = hints.get(pname, str)
        if type(None) in typing.get_args(kind):  # X | None: an X, None the default
            kind = next(a for a in typing.get_args(kind) if a is not type(None))
        origin, args = typing.get_origin(kind), typing.get_args(kind)
        text = helps.get(pname, "")
        flag = "--" + pname.replace("_", "-")
        if param.default is inspect.Parameter.empty:
            ap.add_argument(pname, type=kind if kind in (int, float, Path) else str, help=text)
            continue
        options: dict = {"dest": pname, "default": param.default,
                         "help": f"{text} (default {param.default!r})"}
        if kind is bool:
            options["action"] = argparse.BooleanOptionalAction
        elif origin is typing.Literal:
            options.update(choices=args, type=type(args[0]))
        elif origin in (list, tuple):  # a repeated flag adds its values (--set A=1 --set B=2)
            options.update(nargs="+", type=args[0], action="extend", default=None)
            lists[pname] = param.default
        else:
            options["type"] = kind
        ap.add_argument(flag, **options)
    ap.set_defaults(_lists=lists)
    return ap


def arguments(ap: argparse.ArgumentParser, argv: list[str]) -> dict:
    """The options of ``run`` parsed from ``argv`` (list options not given take their defaults)."""
    args = vars(ap.parse_args(argv))
    for name, default in args.pop("_lists").items():
        if args[name] is None:
            args[name] = default
    return args


def main(argv: list[str] | None = None) -> int:
    """``python -m fbmbench STUDY [options]``; no study: the list of studies and their questions."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print("python -m fbmbench STUDY [--option value ...]  (python -m fbmbench STUDY --help)\n")
        for name in names():
            print(f"  {name:28s} {header(load(name))['Question']}")
        return 0
    module = load(argv[0])
    module.run(**arguments(parser(argv[0], module), argv[1:]))
    return 0
