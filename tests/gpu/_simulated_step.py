"""Run with ``NUMBA_ENABLE_CUDASIM=1`` (or without it on a GPU with the ``gpu`` extra,
benchmarks/device/gpu.sh): one time step of a whole simulation with ``solver.device =
gpu`` (its arrays NumPy's, its kernels run by Numba's CUDA simulator: the residuals, the solves of
the Newton steps and of the particle's rigid responses, the coupling) against the same step on
the CPU with multigrid's smoothers in the GPU's colour order: a disk settling in a closed 8 x 8
box, backward Euler, the implicit coupling (a rigid response per free motion of the disk).
Prints one line; exits 1 where the particle's velocity differs by more than 1e-9 relative
(the two sum in different orders and the solves stop at 1e-8) or the cycles differ, where no
kernel launch was counted (:func:`fbmflow.gpu.launches.count_launches`), or where the step on the
device computes a Newton block's coefficients on the CPU on the whole mesh (the device computes
them; the CPU, for the rigid responses' right-hand sides, only on the cells near the particle),
or the CPU's step never does."""
import os
import sys

import numpy as np

import fbmflow as fb
import fbmflow.flow.levels as levels
import fbmflow.gpu.multigrid as gpu_multigrid
from fbmflow.gpu.device import simulated_backend
from fbmflow.gpu.launches import count_launches
from fbmflow.solvers.multigrid import MultigridSettings

if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":  # the simulator is the GPU here
    gpu_multigrid.gpu_problem = lambda: None
    gpu_multigrid.gpu_backend = simulated_backend


def step(solver: fb.SolverParams):
    """The first step's report and the disk's velocity after it."""
    mesh = fb.StructuredMesh.box((8, 8))
    disk = fb.Particles.at_rest([fb.Ball(0.15, dim=2)], density=1.5, position=[[0.513, 0.55]])
    sim = fb.Simulation(mesh, disk, fb.FluidParams(density=1.0, viscosity=0.1, gravity=10.0),
                        time=fb.TimeParams(dt=0.01, t_end=0.01, scheme="backward-euler"),
                        coupling=fb.CouplingParams(scheme="implicit"), solver=solver)
    report = sim.step(0.01)
    return report, sim.particles.velocity[0].copy()


made = {"coefficients": 0}  # the Newton blocks' coefficients computed on the CPU on the whole mesh
host_coefficients = levels.reaction_coefficients


def counted(space, u, cells=None):
    made["coefficients"] += cells is None
    return host_coefficients(space, u, cells)


levels.reaction_coefficients = counted
cpu, v_cpu = step(fb.SolverParams(linear="multigrid", multigrid=MultigridSettings(order="colours")))
on_cpu, made["coefficients"] = made["coefficients"], 0
counts = count_launches()
gpu, v_gpu = step(fb.SolverParams(device="gpu"))
difference = float(np.abs(v_gpu - v_cpu).max() / np.abs(v_cpu).max())
same = cpu.linear.iterations == gpu.linear.iterations and cpu.linear.solves == gpu.linear.solves
print(f"one step: disk velocity CPU {v_cpu} / device {v_gpu}, relative difference {difference:.1e}; "
      f"linear solves {cpu.linear.solves} / {gpu.linear.solves}, cycles {cpu.linear.iterations} / "
      f"{gpu.linear.iterations}; {counts['launches']} kernel launches; Newton coefficients computed on the "
      f"CPU on the whole mesh {on_cpu} / {made['coefficients']} times", flush=True)
sys.exit(0 if difference <= 1e-9 and same and v_cpu[1] < 0.0 and counts["launches"] > 0
         and made["coefficients"] == 0 < on_cpu else 1)
