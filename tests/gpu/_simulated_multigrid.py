"""Run with ``NUMBA_ENABLE_CUDASIM=1`` (or without it on a GPU with the ``gpu`` extra: CuPy's arrays,
benchmarks/device/gpu.sh): a multigrid solve on the device
(:class:`fbmflow.gpu.multigrid.DeviceMultigridSolver`, its arrays NumPy's and its kernels run by
Numba's CUDA simulator) against the CPU's multigrid with the smoothers in the same colour order,
on the Newton systems of a time step: a 2D closed box with a sharp-boundary disk (the Picard
hierarchy, the mean-pressure border, agglomerated patches) and a 3D box whose Newton block has
moved to another iterate (the reaction term and the drift's convection applied without a matrix).
The flow problem with the device's solver computes its Newton residual and its time step's
mass and spatial terms on the device (:class:`fbmflow.gpu.space.DeviceSpace`, the space's cells
copied once, shared with the Newton block's terms; the residual's gradient and continuity rows by
:class:`fbmflow.gpu.operator.DeviceDivergenceProducts`, from the operator's copies of the
divergence and its transpose). Prints one line per case; exits 1 where the
cycles differ or the velocities by more than 1e-10 relative (the two sum in different orders; a
wrong operation shows at the solves' tolerance, 1e-6), where the residual and terms differ from
the CPU's by more than 1e-13 relative or are not computed on the device, where a level's
smoother holds its own copy of the velocity rows or the divergence its operator holds, where a
level's operator, prolongation or restriction differs from the CPU level's by more than 1e-14
relative, where a second set-up of the system copies a level's divergence, transfers or scalar
pattern again,
or where a moved Newton block's coefficients are not computed on the device alone or differ from
the CPU's by more than 1e-14 relative."""
import os
import sys

import numpy as np
from numba import cuda

from fbmflow.coupling import node_owner, rigid_body_constraints, sharp_boundary
from fbmflow.flow import NavierStokesProblem, NoSlip
from fbmflow.gpu.device import gpu_backend, simulated_backend
from fbmflow.gpu.multigrid import DeviceHierarchy, DeviceMultigridSolver
from fbmflow.gpu.operator import DeviceDivergenceProducts, kept_continuity, kept_gradient
from fbmflow.gpu.space import DeviceSpace, device_space
from fbmflow.mesh import StructuredMesh
from fbmflow.particles import Ball
from fbmflow.solvers import MultigridSolver

assert cuda.is_available()
RTOL = 1e-6


def disk(solver):
    """Backward Euler (dt 0.01) in a closed 8 x 8 box with a sharp-boundary disk moving down."""
    mesh = StructuredMesh.box((8, 8))
    centre, shapes = np.array([[0.513, 0.521]]), [Ball(0.3, 2)]
    vel, ang = np.array([[0.0, -1.0]]), np.zeros(1)

    def ball(V, t):
        owner = node_owner(V, centre, shapes)
        rigid = rigid_body_constraints(V, owner, centre, vel, ang)
        if V is not prob.space.V:  # a coarse level: its own nodes inside the disk
            return rigid
        return sharp_boundary(prob.space, owner, centre, shapes).constraints(rigid, vel, ang)

    prob = NavierStokesProblem(mesh, 0.01, {t: NoSlip() for t in mesh.tags}, extra_constraints=ball,
                               linear_solver=solver)
    x = prob.zero_state()
    return prob, x, prob.linear_system(x, 100.0, 1.0, prob.constraints())


def box(solver):
    """A 4 x 2 x 2 box, a time step's Newton system at a random flow, moved to another iterate
    (its drift applied without a matrix)."""
    mesh = StructuredMesh.box((4, 2, 2))
    prob = NavierStokesProblem(mesh, 0.01, {t: NoSlip() for t in mesh.tags}, linear_solver=solver,
                               coarse_cells=2)
    rng = np.random.default_rng(3)
    x = prob.zero_state()
    x[:prob.space.n_u] = 0.1 * rng.standard_normal(prob.space.n_u)
    system = prob.linear_system(x, 100.0, 1.0, prob.constraints())
    system.A.relinearise(x[:prob.space.n_u] + 0.05 * rng.standard_normal(prob.space.n_u))
    return prob, x, system


backend = simulated_backend() if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1" else gpu_backend()
worst = 0.0
cases = {"2D, sharp disk": disk, "3D, Newton block moved": box}
for name in sys.argv[1:] or cases:
    make = cases[name]
    results = []
    for solver in (MultigridSolver(rtol=RTOL, order="colours"),
                   DeviceMultigridSolver(rtol=RTOL, backend=backend)):
        prob, state, system = make(solver)
        rng = np.random.default_rng(7)
        f, g = rng.standard_normal(system.n_u), rng.standard_normal(system.n_p)
        # the flow problem's Newton residual and its time step's right-hand side terms: on the
        # device where the solver is the device's
        ops = np.concatenate([prob.residual(state, 100.0, 1.0, f, prob.constraints()),
                              prob.apply_mass(state[:system.n_u]), prob.apply_spatial(state[:system.n_u])])
        if system.fixed is not None:
            f[system.fixed] = 0.0
        factor = solver.factor(system)
        u, p, report = factor.solve(f, g)
        results.append((np.concatenate([u, p]), report, factor, ops, prob))
    (x_cpu, cpu, _, ops_cpu, _), (x_gpu, gpu, device, ops_gpu, prob) = results
    assert isinstance(device, DeviceHierarchy)
    on_device = (isinstance(getattr(prob._mass_laplace, "__self__", None), DeviceSpace)
                 and isinstance(prob._divergence, DeviceDivergenceProducts))
    # one copy of the space's cells on the device: the Newton block's terms use the residual's;
    # one of the divergence and its transpose: the residual's gradient and continuity rows use
    # the operator's
    one_copy = ((not device.operator.free or device.operator.space is device_space(prob.space, backend))
                and kept_gradient(backend, prob.BT) is device.operator.blocks.B
                and kept_continuity(backend, prob.BT) is device.operator.blocks.D)
    # a moved Newton block's coefficients computed on the device, the CPU's left unmade, equal
    # to the CPU's when it makes them
    coefficients = "-"
    if device.operator.free:
        A = device.operator.system.A
        unmade = A._react is None and A._drift is None
        made = [(device.operator.react, A.react), (device.operator.drift, A.drift)]
        unmade = unmade and all((d is None) == (h is None) for d, h in made)
        coefficients = max([float(np.abs(backend.get(d).astype(float) - h).max() / np.abs(h).max())
                            for d, h in made if d is not None and h is not None] + [0.0])
        worst = max(worst, coefficients / 1e-14, 0.0 if unmade else 2.0)
        coefficients = f"{coefficients:.1e} (on the device only {unmade})"
    residual = float(np.abs(ops_gpu - ops_cpu).max() / np.abs(ops_cpu).max())
    worst = max(worst, residual / 1e-13, 0.0 if on_device and one_copy else 2.0)
    error = float(np.abs(x_gpu[:system.n_u] - x_cpu[:system.n_u]).max() / np.abs(x_cpu[:system.n_u]).max())
    same = cpu.iterations == gpu.iterations and cpu.converged and gpu.converged
    # every level's smoother reads its scalar rows from the operator's copy on the device
    shared = all(lv.smoother.op[3] is (lv.operator.blocks.S if lv.operator.blocks.S is not None
                                        else lv.operator.blocks.A).data for lv in device.levels)
    worst = max(worst, error / 1e-10, 0.0 if same and shared else 2.0)
    # every level's operator, prolongation and restriction against the CPU level's, and the
    # level's divergence, transfers and scalar pattern copied once: the smoother reads its
    # gradient rows from the operator's copy, and a second set-up of the same system copies none
    # of them again
    again = solver.factor(system)
    reused = all(b.operator.blocks.D is a.operator.blocks.D and b.transfer.P_v is a.transfer.P_v
                 and (a.operator.blocks.S is None
                      or backend.xp.shares_memory(b.operator.blocks.S.indices, a.operator.blocks.S.indices))
                 and a.operator.blocks.divergence is not None
                 and backend.xp.shares_memory(a.smoother.op[7], a.operator.blocks.D.data)
                 for a, b in zip(device.levels, again.levels))
    level_error = 0.0
    for host, level in zip(device.host.levels, device.levels):
        x = rng.standard_normal(host.n_u + host.n_p)
        r, e = rng.standard_normal(host.P.shape[0]), rng.standard_normal(host.P.shape[1])
        for want, got in ((host.system.apply(x), level.operator.apply(backend.put(x))),
                          (host.P.prolongate(e), level.transfer.prolongate(backend.put(e))),
                          (host.P.restrict(r), level.transfer.restrict(backend.put(r)))):
            level_error = max(level_error, float(np.abs(backend.get(got) - want).max() / np.abs(want).max()))
    worst = max(worst, level_error / 1e-14, 0.0 if reused else 2.0)
    per_unknown = device.nbytes / (system.n_u + system.n_p)
    print(f"{name}: {len(device.levels) + 1} levels, cycles CPU {cpu.iterations} / device {gpu.iterations}, "
          f"velocity relative difference {error:.1e}, device memory {per_unknown:.0f} bytes per unknown, "
          f"scalar rows shared {shared}; residual on the device {on_device} (cells copied once {one_copy}), "
          f"relative difference {residual:.1e}; levels' operators and transfers {level_error:.1e} from the "
          f"CPU's, divergence, transfers and pattern copied once {reused}; "
          f"Newton coefficients {coefficients}",
          flush=True)
sys.exit(0 if worst <= 1.0 else 1)
