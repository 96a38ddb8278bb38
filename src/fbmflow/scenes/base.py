"""The scene contract: a named, validated set-up that runs and reports named quantities.

A scene defines its parameter dataclass, its mesh at refinement level 0 (each level halves h) and
its default level, a ``run`` that returns a :class:`SceneResult`, and optionally a ``plot`` of
its key curves. One scene library feeds the command line, the tests, the benchmarks and the
examples.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable

log = logging.getLogger(__name__)

Progress = Callable[[int, int, float | None], None]  # (step, n_steps, time or None if steady)


@dataclass
class SceneResult:
    """What a scene run produced.

    quantities : flat dict of named results (numbers or lists of numbers)
    """

    quantities: dict[str, Any]
    n_cells: int
    n_dofs: int
    steps: int = 0
    newton_iterations: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


class Scene:
    """Base class of the built-in scenes (subclasses set the class attributes)."""

    name: str = ""
    description: str = ""
    Params: type = object
    default_level: int = 0
    max_level: int = 8

    def run(self, params, level: int, progress: Progress | None = None) -> SceneResult:
        raise NotImplementedError

    def plot(self, summary: dict, path) -> bool:
        """Save a PNG of the key curves of a finished run; False when the scene has none."""
        return False
