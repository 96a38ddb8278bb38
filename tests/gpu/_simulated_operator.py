"""Run with ``NUMBA_ENABLE_CUDASIM=1`` (or without it on a GPU, benchmarks/device/gpu.sh): the GPU's
operators (:mod:`fbmflow.gpu.operators`) under Numba's CUDA simulator against the CPU kernels, on
small 2D and 3D meshes (one periodic axis): the cell operator for the mass, Laplace and convection
terms with a given convecting velocity and with ``N(w) w``, the Newton term (each with its colours
in one cooperative launch and in one launch per colour), and the two coefficient
arrays they read. Prints one line per case; exits 1 on a mismatch."""
import sys

import numpy as np
from numba import cuda

from fbmflow.fem import FlowSpace, _kernels
from fbmflow.gpu import (
    apply_cell_operator,
    apply_reaction,
    cell_colours,
    reaction_coefficients,
    velocity_coefficients,
)
from fbmflow.gpu import colours as gpu_colours
from fbmflow.gpu.colours import DeviceColours
from fbmflow.mesh import StructuredMesh

assert cuda.is_available()
worst = 0.0
for shape, periodic in (((6, 4), (True, False)), ((4, 2, 4), (False, False, True))):
    mesh = StructuredMesh.box(shape, periodic=periodic)
    space = FlowSpace(mesh)
    rng = np.random.default_rng(len(shape))
    w = rng.standard_normal((space.dim, space.n_v))
    conv = _kernels.velocity_coefficients(rng.standard_normal((space.dim, space.n_v)), space.V.cell_dofs,
                                          space.phi, space.detJw)
    colours = cell_colours(space.V.cell_dofs)
    for c in colours:  # no two cells of a colour share a node
        nodes = space.V.cell_dofs[c].ravel()
        assert np.unique(nodes).size == nodes.size
    assert np.array_equal(np.sort(np.concatenate(colours)), np.arange(mesh.n_cells))
    on_device = DeviceColours(colours, lambda a, dtype: cuda.to_device(np.ascontiguousarray(a, dtype)))
    for coefficients, c in (((2.0, 0.3, 0.7), conv), ((0.0, 0.0, 1.0), None), ((1.5, 0.0, 0.0), None)):
        want = np.zeros_like(w)
        cpu_conv = np.zeros((0, 0, 0)) if c is None else c  # the CPU's N(w) w: an empty array
        for batch in space.colour_groups:
            _kernels.apply_cell_operator(batch, space.detJw, space.Jinv, space.V.cell_dofs, space.phi,
                                         space.dphi, *coefficients, cpu_conv, w, want)
        geometry = (space.detJw, space.Jinv, space.V.cell_dofs, space.phi, space.dphi)
        device = [cuda.to_device(a) for a in geometry]
        errors = []
        for gpu_colours.ONE_LAUNCH in (True, False):  # every colour in one launch, or one launch each
            out = cuda.to_device(np.zeros_like(w))
            apply_cell_operator(on_device, *device, *coefficients, None if c is None else cuda.to_device(c),
                                cuda.to_device(w), out, threads=4)
            errors.append(float(np.abs(out.copy_to_host() - want).max() / np.abs(want).max()))
        worst = max(worst, *errors)
        which = "N(w)" if c is None else c.shape
        print(f"{mesh.dim}D {shape}, alpha beta gamma {coefficients}, conv {which}: relative error "
              f"{errors[0]:.1e} in one launch, {errors[1]:.1e} in one launch per colour ({len(colours)})",
              flush=True)
    u = rng.standard_normal((space.dim, space.n_v))
    d_u = cuda.to_device(u)
    conv_gpu = cuda.to_device(np.zeros_like(conv))
    velocity_coefficients(d_u, device[2], device[3], device[0], conv_gpu, threads=4)
    want = _kernels.velocity_coefficients(u, space.V.cell_dofs, space.phi, space.detJw)
    error = float(np.abs(conv_gpu.copy_to_host() - want).max() / np.abs(want).max())
    worst = max(worst, error)
    print(f"{mesh.dim}D {shape}, velocity coefficients: relative error {error:.1e}", flush=True)
    react = _kernels.reaction_coefficients(u, space.V.cell_dofs, space.phi, space.dphi, space.detJw,
                                           space.Jinv)
    react_gpu = cuda.to_device(np.zeros_like(react))
    reaction_coefficients(d_u, device[2], device[3], device[4], device[0], device[1], react_gpu, threads=4)
    error = float(np.abs(react_gpu.copy_to_host() - react).max() / np.abs(react).max())
    worst = max(worst, error)
    print(f"{mesh.dim}D {shape}, reaction coefficients: relative error {error:.1e}", flush=True)
    want = np.zeros_like(w)
    for batch in space.colour_groups:
        _kernels.apply_reaction(batch, react, space.V.cell_dofs, space.phi, w, 0.8, want)
    errors = []
    for gpu_colours.ONE_LAUNCH in (True, False):
        out = cuda.to_device(np.zeros_like(w))
        apply_reaction(on_device, cuda.to_device(react), device[2], device[3], cuda.to_device(w), 0.8, out,
                       threads=4)
        errors.append(float(np.abs(out.copy_to_host() - want).max() / np.abs(want).max()))
    worst = max(worst, *errors)
    print(f"{mesh.dim}D {shape}, Newton term: relative error {errors[0]:.1e} in one launch, {errors[1]:.1e} "
          "in one launch per colour", flush=True)
sys.exit(0 if worst < 1e-13 else 1)
