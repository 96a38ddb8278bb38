"""Field output for ParaView: the flow on the Q2 nodes as an XDMF (+HDF5) time series, the
particles as one VTU per output time with a ParaView collection (``.pvd``).

The Q2 nodes of a structured mesh form a lattice with twice the cells per axis; the output mesh
is that lattice (quads in 2D, hexahedra in 3D, each Q2 cell split into ``2^dim`` sub-cells), so
every velocity value is written where it is computed. Point data: ``velocity`` (3 components),
``owner`` (particle index, -1 in the fluid), ``vorticity`` (magnitude, from central differences on
the lattice). Cell data: ``pressure``, the P1disc pressure at each sub-cell's centre. On periodic
axes the strip of sub-cells that would wrap around is left out. Particles: points at the centres
with ``id``, ``radius`` (bounding), ``velocity``, ``angular_velocity`` and ``force``.

The XDMF series (written here with h5py: one mesh, one group of arrays per time in the ``.h5``
file beside it) has its XML index rewritten after every output, so a killed run leaves a
readable series up to its last output; a resumed run starts a new series
(``fields_from_<step>.xdmf``) next to the first one. meshio reads it back
(``meshio.xdmf.TimeSeriesReader``). The VTU option writes one ``fields_<step>.vtu`` per output
and a ``fields.pvd`` collection instead.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _pad3(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float).reshape(len(a), -1)
    return np.pad(a, ((0, 0), (0, 3 - a.shape[1]))) if a.shape[1] < 3 else a


class _Collection:
    """A ParaView collection file (``.pvd``) listing one dataset per time, rewritten on every
    addition; a resumed run keeps the entries already there."""

    def __init__(self, path: Path, keep: bool):
        import xml.etree.ElementTree as ET

        self.path = path
        self.entries: list[tuple[float, str]] = []
        if keep and path.is_file():
            self.entries = [(float(e.get("timestep")), e.get("file"))
                            for e in ET.parse(path).getroot().iter("DataSet")]

    def add(self, t: float, name: str) -> None:
        self.entries.append((t, name))
        rows = "\n".join(f'    <DataSet timestep="{t!r}" file="{f}"/>' for t, f in self.entries)
        self.path.write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                             f"  <Collection>\n{rows}\n  </Collection>\n</VTKFile>\n")


class FieldWriter:
    """Writes the flow (``fields*.xdmf``, or with ``fmt = "vtu"`` ``fields_<step>.vtu`` and
    ``fields.pvd``) and the particles (``particles_<step>.vtu`` and ``particles.pvd``) into ``out``.

    Parameters
    ----------
    out : directory; space : the :class:`~fbmflow.fem.space.FlowSpace`; start_step : 0 for a new run,
    the checkpoint's step for a resumed one; fmt : ``xdmf`` or ``vtu``
    """

    def __init__(self, out, space, start_step: int = 0, fmt: str = "xdmf"):
        import h5py

        if fmt not in ("xdmf", "vtu"):
            raise ValueError(f"field output format must be 'xdmf' or 'vtu', got {fmt!r}")
        self.fmt = fmt
        self.out = Path(out)
        self.space = space
        V, mesh = space.V, space.mesh
        self.dim = mesh.dim
        self.shape = tuple(V.lattice_shape)
        self.points = _pad3(V.coordinates)
        # sub-cells of the node lattice, x fastest, corners in VTK order
        idx = np.indices([s - 1 for s in self.shape]).reshape(self.dim, -1, order="F").T
        if self.dim == 2:
            corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
        else:
            corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                                [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
        self.cells = V._lattice_to_dof(idx[:, None, :] + corners[None, :, :])
        # the Q2 cell of every sub-cell and where its centre lies in the cell's P1disc frame
        self.parent = (idx // 2 * np.cumprod((1,) + tuple(mesh.shape[:-1]))).sum(axis=1)
        self.rel = np.where(idx % 2 == 0, -0.5, 0.5)
        self.cell_type = "Quadrilateral" if self.dim == 2 else "Hexahedron"
        self._times: list[tuple[float, dict, dict]] = []  # time, point fields, cell fields (shapes)
        if fmt == "xdmf":
            stem = "fields" if start_step == 0 else f"fields_from_{start_step:06d}"
            self._xdmf, self._h5 = self.out / f"{stem}.xdmf", self.out / f"{stem}.h5"
            with h5py.File(self._h5, "w") as f:
                f["points"] = self.points
                f["cells"] = self.cells
        else:
            self._fields = _Collection(self.out / "fields.pvd", keep=start_step > 0)
        self._particles = _Collection(self.out / "particles.pvd", keep=start_step > 0)

    def vorticity(self, u: np.ndarray) -> np.ndarray:
        """``|curl u|`` at the nodes from central differences on the lattice, (n_v,)."""
        dim, n_v = self.dim, self.space.n_v
        axes = self.space.V.lattice_axes
        comp = [u[a * n_v:(a + 1) * n_v].reshape(self.shape, order="F") for a in range(dim)]
        grad = [[np.gradient(comp[a], axes[b], axis=b) for b in range(dim)] for a in range(dim)]
        if dim == 2:
            w = grad[1][0] - grad[0][1]
        else:
            w = np.sqrt((grad[2][1] - grad[1][2])**2 + (grad[0][2] - grad[2][0])**2
                        + (grad[1][0] - grad[0][1])**2)
        return np.abs(w).ravel(order="F")

    def write(self, step: int, t: float, x: np.ndarray, owner: np.ndarray, particles,
              force: np.ndarray) -> None:
        """The flow ``x`` and the particles at time ``t`` (output number ``step``)."""
        import meshio

        s, dim = self.space, self.dim
        u = x[:s.n_u]
        p = x[s.n_u:].reshape(-1, dim + 1)[self.parent]
        pressure = p[:, 0] + np.einsum("ka,ka->k", p[:, 1:], self.rel)
        velocity = _pad3(u.reshape(dim, s.n_v).T)
        point = {"velocity": velocity, "owner": owner.astype(np.int64), "vorticity": self.vorticity(u)}
        if self.fmt == "xdmf":
            self._append(t, point, {"pressure": pressure})
        else:
            name = f"fields_{step:06d}.vtu"
            cells = [("quad" if dim == 2 else "hexahedron", self.cells)]
            meshio.write(self.out / name, meshio.Mesh(self.points, cells, point_data=point,
                                                      cell_data={"pressure": [pressure]}))
            self._fields.add(t, name)
        n = particles.n
        name = f"particles_{step:06d}.vtu"
        meshio.write(self.out / name, meshio.Mesh(
            _pad3(particles.position), [("vertex", np.arange(n)[:, None])],
            point_data={"id": np.arange(n), "radius": particles.bounding_radius,
                        "velocity": _pad3(particles.velocity),
                        "angular_velocity": _pad3(np.reshape(particles.angular_velocity, (n, -1))),
                        "force": _pad3(force)}))
        self._particles.add(t, name)

    def _append(self, t: float, point: dict, cell: dict) -> None:
        import h5py

        k = len(self._times)
        with h5py.File(self._h5, "a") as f:
            for name, value in {**point, **cell}.items():
                f[f"step{k}/{name}"] = value
        self._times.append((t, {n: v.shape for n, v in point.items()}, {n: v.shape for n, v in cell.items()}))
        self._write_xdmf()

    def _write_xdmf(self) -> None:
        h5, n_pts, n_cells = self._h5.name, len(self.points), len(self.cells)

        def item(path, shape, kind="Float", precision=8):
            dims = " ".join(str(d) for d in shape)
            return (f'<DataItem DataType="{kind}" Dimensions="{dims}" Format="HDF" Precision="{precision}">'
                    f"{h5}:/{path}</DataItem>")

        grids = []
        for k, (t, point, cell) in enumerate(self._times):
            attrs = []
            for centre, fields in (("Node", point), ("Cell", cell)):
                for name, shape in fields.items():
                    kind = "Vector" if len(shape) == 2 else "Scalar"
                    dtype = "Int" if name == "owner" else "Float"
                    attrs.append(f'<Attribute Name="{name}" AttributeType="{kind}" Center="{centre}">'
                                 f"{item(f'step{k}/{name}', shape, dtype)}</Attribute>")
            grids.append(
                f'<Grid Name="step{k}" GridType="Uniform"><Time Value="{t!r}"/>'
                f'<Topology TopologyType="{self.cell_type}" NumberOfElements="{n_cells}">'
                f"{item('cells', self.cells.shape, 'Int')}</Topology>"
                f'<Geometry GeometryType="XYZ">{item("points", (n_pts, 3))}</Geometry>' + "".join(attrs)
                + "</Grid>")
        self._xdmf.write_text('<?xml version="1.0"?>\n<Xdmf Version="3.0"><Domain>'
                              '<Grid Name="fields" GridType="Collection" CollectionType="Temporal">'
                              + "".join(grids) + "</Grid></Domain></Xdmf>\n")
