"""Point location and sampling on tensor-product meshes, uniform and graded."""
import numpy as np
import pytest

from fbmflow.fem import FlowSpace
from fbmflow.fem.functions import locate, sample_velocity
from fbmflow.mesh import StructuredMesh


@pytest.mark.parametrize("dim", [2, 3])
def test_sampling_on_a_graded_mesh_is_exact_for_q2_fields(dim):
    """A field in the Q2 space (here x^2 y - z, triquadratic) is sampled exactly at random points;
    ``locate`` returns the containing cell and reference coordinates that map back to the point."""
    axes = [np.array([0.0, 0.05, 0.1, 0.4, 1.0]), np.array([0.0, 0.6, 0.7, 2.0]),
            np.array([-1.0, -0.2, 1.0])][:dim]
    space = FlowSpace(StructuredMesh.rectilinear(axes))
    X = space.V.coordinates

    def f(x):
        return x[:, 0] ** 2 * x[:, 1] - (x[:, 2] if dim == 3 else 0.0)

    u = np.concatenate([f(X)] + [np.zeros(space.n_v)] * (dim - 1))
    rng = np.random.default_rng(0)
    pts = rng.uniform([a[0] for a in axes], [a[-1] for a in axes], (200, dim))
    np.testing.assert_allclose(sample_velocity(space, u, pts)[:, 0], f(pts), atol=1e-12)
    cells, xi = locate(space.mesh, pts)
    for k in range(10):
        back = space.mesh.map_to_physical(xi[k:k + 1], cells[k:k + 1])[0, 0]
        np.testing.assert_allclose(back, pts[k], atol=1e-13)
    assert np.all(np.abs(xi) <= 1 + 1e-12)
    with pytest.raises(ValueError, match="outside"):
        locate(space.mesh, np.full((1, dim), 5.0))
