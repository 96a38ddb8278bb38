"""The command line and scene contract (issue 2, item 6)."""
import json
import os
import subprocess
import sys

import pytest

from fbmflow import __version__
from fbmflow.cli import main
from fbmflow.scenes import SCENES

REQUIRED = {"scene", "fbmflow_version", "params", "level", "n_cells", "n_dofs", "steps",
            "wall_time_s", "newton_iterations", "quantities", "linear_solver"}


def test_scenes_lists_one_per_line(capsys):
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split("  ")[0] for line in lines] == list(SCENES)
    assert all(len(line.split("  ", 1)[1]) > 10 for line in lines)


def test_run_as_a_separate_process(tmp_path):
    """The installed console script runs a scene and writes summary.json and its plot."""
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "fbmflow.cli", "run", "channel-2d", "--level", "1",
                           "--set", "fluid.viscosity=0.02", "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert REQUIRED <= set(summary)
    assert summary["fbmflow_version"] == __version__
    assert summary["params"]["fluid"]["viscosity"] == 0.02
    assert summary["level"] == 1 and summary["n_cells"] == 8 * 2
    assert summary["linear_solver"] == "direct (SuperLU)"  # 2D and small: SuperLU, PARDISO or not
    if sys.platform != "win32":  # the process's measured peak: above the interpreter's, below 8 GB
        peak = summary["peak_memory_gb"] * 1e9
        assert 5e7 < peak < 8e9
        assert summary["bytes_per_unknown"] == pytest.approx(peak / summary["n_dofs"])
    q = summary["quantities"]
    assert q["max_velocity_error"] < 1e-10
    assert q["pressure_drop"] == pytest.approx(32 * 0.02, rel=1e-10)


def test_scene_file_with_overrides(tmp_path, capsys):
    scene = tmp_path / "my.toml"
    scene.write_text('scene = "cavity-2d"\nlevel = 0\n[fluid]\nre = 50\n')
    out = tmp_path / "o"
    assert main(["run", str(scene), "--set", "fluid.re=80", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["params"]["fluid"]["re"] == 80 and summary["level"] == 0
    assert len(summary["quantities"]["u_vertical_centerline"]) == 129
    assert (out / "cavity-2d.png").stat().st_size > 1000
    assert main(["plot", str(out)]) == 0


@pytest.mark.parametrize("argv, needle", [
    (["run", "no-such-scene"], "unknown scene 'no-such-scene'"),
    (["run", "cavity-2d", "--set", "fluid.viscosity=1"], "unknown parameter 'fluid.viscosity'"),
    (["run", "cavity-2d", "--set", "fluid.re=-5"], "fluid.re: must be positive"),
    (["run", "cavity-2d", "--set", "fluid.re=fast"], "fluid.re: expected a number"),
    (["run", "cavity-2d", "--set", "solver.linear=magic"], "solver.linear: 'magic' is not allowed"),
    (["run", "cavity-2d", "--set", "fluid"], "--set expects KEY=VALUE"),
    (["run", "cavity-2d", "--level", "99"], "level must be an integer from 0 to"),
    (["run", "taylor-green-2d", "--set", "time.dt=0"], "time.dt: must be positive"),
    (["run", "taylor-green-2d", "--set", "time.scheme=rk4"], "time.scheme: 'rk4' is not allowed"),
    (["run", "missing.toml"], "scene file 'missing.toml' not found"),
    (["run", "cavity-2d", "--bogus"], "unrecognized arguments"),
    (["plot", "/nonexistent-dir"], "not found"),
])
def test_bad_input_exits_2_with_one_line(argv, needle, capsys):
    assert _exit_code(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err
    assert "Traceback" not in err


def test_bad_scene_files(tmp_path, capsys):
    cases = {
        "nosc.toml": ("[fluid]\nre = 1\n", "lacks the key 'scene'"),
        "bad.toml": ("scene = cavity-2d\n", "not valid TOML"),
        "unknownsec.toml": ('scene = "cavity-2d"\n[fluidd]\nre = 1\n', "unknown parameter 'fluidd'"),
        "wrongtype.toml": ('scene = "cavity-2d"\n[fluid]\nre = "high"\n', "fluid.re: expected a number"),
        "section.toml": ('scene = "cavity-2d"\nfluid = 3\n', "expected a table"),
    }
    for name, (text, needle) in cases.items():
        path = tmp_path / name
        path.write_text(text)
        assert main(["run", str(path)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and needle in err, (name, err)


def _exit_code(argv) -> int:
    """``main``'s return value, or the status of the SystemExit that argparse raises."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def test_public_api_is_lazy_and_complete():
    code = ("import sys, fbmflow; assert 'numba' not in sys.modules; "
            "[getattr(fbmflow, n) for n in fbmflow.__all__]; print('ok')")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.stdout.strip() == "ok", proc.stderr


def test_newton_failure_names_step_time_and_remedy(capsys, tmp_path):
    """A run that cannot converge exits 1 with the step, the time and a remedy, no traceback."""
    code = main(["run", "taylor-green-2d", "--level", "0", "--set", "solver.newton_max_iterations=1",
                 "--set", "solver.newton_rtol=1e-14", "--set", "solver.newton_atol=1e-300",
                 "--out", str(tmp_path), "--quiet", "--no-plot"])
    err = capsys.readouterr().err
    assert code == 1
    assert "step 1 (t = 0" in err and "Remedy" in err and "Traceback" not in err


def test_output_paths_that_cannot_hold_a_run_exit_2(tmp_path, capsys):
    """``--out`` naming a file, lying below a file, empty, or not writable: one line, exit 2."""
    afile = tmp_path / "afile"
    afile.write_text("x")
    cases = [(str(afile), "is a file"), (str(afile / "below"), "cannot write"), ("", "empty")]
    if os.geteuid() != 0:  # root writes anywhere but /proc
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        cases.append((str(locked / "x"), "cannot write"))
    cases.append(("/proc/fbmflow-test", "cannot write"))
    for out, needle in cases:
        code = main(["run", "taylor-green-2d", "--level", "0", "--out", out, "--quiet", "--no-plot"])
        assert code == 2, out
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (out, err)


def test_plot_of_a_damaged_summary_exits_2(tmp_path, capsys):
    (tmp_path / "summary.json").write_text("{not json")
    assert main(["plot", str(tmp_path)]) == 2
    assert "damaged" in capsys.readouterr().err
    (tmp_path / "summary.json").write_text(json.dumps({"scene": "glowinski-free-fall"}))
    assert main(["plot", str(tmp_path)]) == 2
    assert "does not hold what" in capsys.readouterr().err


def test_progress_writes_lines_where_no_terminal_reads_them():
    """A log file gets plain lines, at most one every ``every`` seconds, and always the last."""
    import io

    from fbmflow.run import Progress

    log = io.StringIO()
    progress = Progress(every=1e9, stream=log)
    for step in range(26, 131):
        progress(step, 130, step * 0.01, {"newton": 3, "max|U|": 0.25})
    lines = log.getvalue().splitlines()
    assert lines == ["step 26/130  t = 0.26  newton 3  max|U| 0.25",
                     "step 130/130  t = 1.3  newton 3  max|U| 0.25"]


def test_progress_on_a_terminal_is_a_bar_that_starts_where_a_resumed_run_does():
    """tqdm, started at the resumed step: its rate and ETA count only the steps this run made."""
    import io

    from fbmflow.run import Progress

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    screen = Terminal()
    progress = Progress(stream=screen)
    progress(26, 130, 0.26, {"newton": 3})
    assert progress.bar.n == 26 and progress.bar.initial == 25
    progress(130, 130, 1.3, {"newton": 2})
    assert "130/130" in screen.getvalue() and "newton=2" in screen.getvalue()


def test_a_particle_that_leaves_the_box_stops_the_run_with_a_remedy_that_fits(tmp_path, capsys):
    """Glowinski's disk at dt = 0.1 s falls through the floor (it exited 0, 27 cm below the box);
    now the step that takes it half its radius into the floor fails: exit 1, the step, the wall,
    wall contact and a smaller time step as remedies, and a checkpoint of the last state that
    passed the check."""
    import h5py

    code = main(["run", "glowinski-free-fall", "--level", "0", "--quiet", "--no-plot", "--set", "time.dt=0.1",
                 "--set", "time.t_end=1.0", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 1 and "into the wall y = 0" in err and "contact.enabled = true" in err, err
    assert "reduce time.dt" in err
    with h5py.File(tmp_path / "checkpoint.h5") as f:
        y = f["position"][()][0, 1]
    assert y > 0.125 * (1 - 0.5)  # the disk's centre at most half its radius into the floor


def test_an_overlap_from_a_contact_skin_wider_than_the_gaps_names_the_skin_not_the_step(tmp_path, capsys):
    """``sedimentation-3d`` at level 0: cells of 0.25 cm against spheres of radius 0.1 cm, so the
    contact skin (one cell) is 2.5 radii and the lattice's gaps (0.14 cm) lie inside it; the
    contact pushes the lattice apart in the first step, a sphere into another, whatever the time
    step (it said "reduce time.dt"). The remedy now names the level and the skin."""
    code = main(["run", "sedimentation-3d", "--level", "0", "--quiet", "--no-plot", "--set",
                 "time.t_end=0.02", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 1 and "into particle" in err, err
    assert "--level" in err and "contact.skin_cells" in err and "2.5 particle radii" in err, err
    assert "reduce time.dt" not in err


def test_a_particle_leaving_a_graded_mesh_s_fine_zone_is_warned_of_once(tmp_path, caplog):
    """A light disk rises out of Glowinski's fine zone (it ran 2.3 times as fast as on a uniform
    mesh there, and nothing warned): one warning naming the step, the cells and the remedy."""
    code = main(["run", "glowinski-free-fall", "--level", "0", "--quiet", "--no-plot", "--set",
                 "particle.density=0.5", "--set", "time.t_end=0.3", "--out", str(tmp_path)])
    warned = [r.getMessage() for r in caplog.records if "fine zone" in r.getMessage()]
    assert code == 0 and len(warned) == 1 and "domain.mesh = uniform" in warned[0], warned


@pytest.mark.parametrize("size, rank", [("OMPI_COMM_WORLD_SIZE", "OMPI_COMM_WORLD_RANK"),
                                        ("PMI_SIZE", "PMI_RANK")])
def test_several_processes_without_mpi_stop_before_any_work_with_one_line(size, rank, tmp_path, monkeypatch,
                                                                          capsys):
    """Started by a launcher as 2 processes (its variables) where mpi4py is missing, ``run`` and
    ``resume`` exit 2 on both, the first with one line naming the remedy (the ``mpi`` extra), the
    other silent; nothing is written. One process (size 1) runs as usual."""
    monkeypatch.setitem(sys.modules, "mpi4py", None)
    out = tmp_path / "out"
    for r, lines in (("0", 1), ("1", 0)):
        monkeypatch.setenv(size, "2")
        monkeypatch.setenv(rank, r)
        for argv in (["run", "cavity-2d", "--level", "0", "--out", str(out), "--quiet"],
                     ["resume", str(out)]):
            assert main(argv) == 2
            err = capsys.readouterr().err
            assert err.count("\n") == lines and (not lines or '".[mpi]"' in err and "mpi4py" in err)
    assert not out.exists()
    monkeypatch.setenv(size, "1")
    monkeypatch.setenv(rank, "0")
    assert main(["run", "cavity-2d", "--level", "0", "--out", str(out), "--quiet", "--no-plot",
                 "--set", "fluid.re=10"]) == 0
