"""What linear solves report: one solve's work, and the solves of a run counted together."""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class LinearReport:
    """Work done by one linear solve."""

    solver: str
    wall_time_s: float
    iterations: int = 0
    residuals: list[float] = field(default_factory=list)
    smoothing_sweeps: int = 0
    setup_time_s: float = 0.0
    factor_time_s: float = 0.0  # of the set-up: the smoothers' local factors (factored Vanka)
    converged: bool = True  # an iterative solver that missed its target says so here


@dataclass
class LinearWork:
    """Linear solves counted together (a flow problem's since its creation; differences of two
    counts give one time step's): solves, iterations (multigrid: preconditioned FGMRES steps,
    one cycle each), smoothing sweeps summed over all levels, and wall time including set-up."""

    solves: int = 0
    iterations: int = 0
    sweeps: int = 0
    time_s: float = 0.0

    def add(self, report: LinearReport) -> None:
        self.solves += 1
        self.iterations += report.iterations
        self.sweeps += report.smoothing_sweeps
        self.time_s += report.wall_time_s

    def since(self, earlier: "LinearWork") -> "LinearWork":
        return LinearWork(self.solves - earlier.solves, self.iterations - earlier.iterations,
                          self.sweeps - earlier.sweeps, self.time_s - earlier.time_s)
