"""ParaView output reads back with meshio: mesh, fields, shapes, times; particles per output."""
import numpy as np
import pytest

from fbmflow.cli import main


@pytest.mark.parametrize("scene, level, dim", [("glowinski-free-fall", 0, 2), ("sedimentation-3d", 0, 3)])
def test_field_and_particle_output_round_trip(tmp_path, scene, level, dim):
    import h5py
    import meshio

    extra = ["--set", "particles.count=2"] if dim == 3 else []
    assert main(["run", scene, "--level", str(level), "--set", "time.t_end=0.02", "--set", "time.dt=0.005",
                 *extra, "--fields-every", "2", "--quiet", "--no-plot", "--out", str(tmp_path)]) == 0
    with meshio.xdmf.TimeSeriesReader(str(tmp_path / "fields.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        times = []
        for k in range(reader.num_steps):
            t, point_data, cell_data = reader.read_data(k)
            times.append(t)
            n_sub = len(cells[0].data)
            assert point_data["velocity"].shape == (len(points), 3)
            assert point_data["owner"].shape == (len(points),)
            assert point_data["vorticity"].shape == (len(points),)
            assert cell_data["pressure"][0].shape == (n_sub,)
            assert np.all(np.isfinite(point_data["velocity"]))
    assert cells[0].type == ("quad" if dim == 2 else "hexahedron")
    np.testing.assert_allclose(times, [0.0, 0.01, 0.02])
    last = point_data
    assert (last["owner"] >= 0).any() and np.abs(last["velocity"]).max() > 0.0
    with h5py.File(tmp_path / "run.h5") as f:
        final = f["position"][-1]
    pvd = (tmp_path / "particles.pvd").read_text()
    assert pvd.count("<DataSet") == 3
    m = meshio.read(tmp_path / "particles_000004.vtu")
    np.testing.assert_allclose(m.points[:, :dim], final, atol=1e-12)
    assert set(m.point_data) >= {"id", "radius", "velocity", "angular_velocity", "force"}


def test_vtu_field_output_reads_back(tmp_path):
    import meshio

    assert main(["run", "glowinski-free-fall", "--level", "0", "--set", "time.t_end=0.01", "--set",
                 "time.dt=0.005", "--fields-every", "1", "--fields-format", "vtu", "--quiet", "--no-plot",
                 "--out", str(tmp_path)]) == 0
    assert (tmp_path / "fields.pvd").read_text().count("<DataSet") == 3
    m = meshio.read(tmp_path / "fields_000002.vtu")
    assert m.cells[0].type == "quad" and m.point_data["velocity"].shape == (len(m.points), 3)
    assert m.cell_data["pressure"][0].shape == (len(m.cells[0].data),)
