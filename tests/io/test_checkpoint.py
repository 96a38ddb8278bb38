"""Checkpoints and run data: a run killed by a signal resumes to the uninterrupted run's final
state; corrupt, mismatched or missing checkpoints are refused with exit status 2."""
import json
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from fbmflow.cli import main

RUN = ["glowinski-free-fall", "--level", "1", "--set", "time.t_end=0.12", "--set", "time.dt=0.005",
       "--checkpoint-every", "4", "--quiet", "--no-plot"]


def _cli(*args):
    return subprocess.Popen([sys.executable, "-m", "fbmflow.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _checkpoint_step(path):
    try:
        with h5py.File(path, "r") as f:
            return json.loads(f.attrs["meta"])["step"]
    except (OSError, KeyError):
        return 0


@pytest.mark.slow
def test_killed_run_resumes_to_the_uninterrupted_final_state(tmp_path):
    killed, whole = tmp_path / "killed", tmp_path / "whole"
    proc = _cli("run", *RUN, "--out", str(killed))
    deadline = time.time() + 300
    while _checkpoint_step(killed / "checkpoint.h5") < 8 and proc.poll() is None and time.time() < deadline:
        time.sleep(0.02)
    assert proc.poll() is None, "the run finished before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (killed / "summary.json").exists()
    resumed = _cli("resume", str(killed), "--quiet", "--no-plot")
    assert resumed.wait() == 0, resumed.stderr.read()
    assert main(["run", *RUN, "--out", str(whole)]) == 0
    a = json.loads((killed / "summary.json").read_text())["quantities"]
    b = json.loads((whole / "summary.json").read_text())["quantities"]
    np.testing.assert_allclose(a["final_position"], b["final_position"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(a["v"], b["v"], rtol=0, atol=1e-12)
    with h5py.File(killed / "run.h5") as f, h5py.File(whole / "run.h5") as g:
        assert f["step"].shape == g["step"].shape == (25,)
        assert np.array_equal(f["step"][()], np.arange(25))
        np.testing.assert_allclose(f["position"][()], g["position"][()], rtol=0, atol=1e-12)


def _short_run(out):
    assert main(["run", "glowinski-free-fall", "--level", "0", "--set", "time.t_end=0.03", "--set",
                 "time.dt=0.005", "--checkpoint-every", "2", "--quiet", "--no-plot", "--out", str(out)]) == 0


def test_run_data_and_csv(tmp_path):
    _short_run(tmp_path)
    with h5py.File(tmp_path / "run.h5") as f:
        assert f["position"].shape == (7, 1, 2) and f["t"][-1] == pytest.approx(0.03)
        assert f.attrs["scene"] == "glowinski-free-fall" and "fbmflow_version" in f.attrs
        assert json.loads(f.attrs["params"])["fluid"]["viscosity"] == 0.1
    lines = (tmp_path / "particles.csv").read_text().splitlines()
    assert lines[0].startswith("step,t,particle,x,y") and len(lines) == 8


def test_corrupt_checkpoint_is_refused(tmp_path, capsys):
    _short_run(tmp_path)
    with h5py.File(tmp_path / "checkpoint.h5", "a") as f:
        f["x"][0] += 1.0  # a flipped value: the checksum no longer matches
    assert main(["resume", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "checksum" in err[0]
    (tmp_path / "checkpoint.h5").write_bytes(b"not an HDF5 file")
    assert main(["resume", str(tmp_path), "--quiet"]) == 2
    assert "unreadable" in capsys.readouterr().err


def test_mismatched_or_missing_checkpoint_is_refused(tmp_path, capsys):
    _short_run(tmp_path)
    info = json.loads((tmp_path / "run.json").read_text())
    info["params"]["fluid"]["viscosity"] = 0.2
    (tmp_path / "run.json").write_text(json.dumps(info))
    assert main(["resume", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()  # the key that differs, not two dictionaries
    assert len(err) == 1 and "params.fluid.viscosity is 0.1 there, 0.2 here" in err[0], err
    (tmp_path / "checkpoint.h5").unlink()
    assert main(["resume", str(tmp_path), "--quiet"]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    assert main(["resume", str(tmp_path / "nowhere"), "--quiet"]) == 2
    assert main(["run", "cavity-2d", "--checkpoint-every", "2", "--out", str(tmp_path / "c")]) == 2


def test_checkpoint_from_before_a_new_parameter_resumes_with_its_default(tmp_path, capsys):
    """A checkpoint written before a parameter existed (here: without fbm.force) matches a run
    that has the parameter at its default, and is refused when the run sets another value."""
    from fbmflow.io import load_checkpoint, save_checkpoint
    assert main(["run", "glowinski-free-fall", "--level", "0", "--set", "time.t_end=0.03", "--set",
                 "time.dt=0.005", "--checkpoint-every", "4", "--quiet", "--no-plot", "--out",
                 str(tmp_path)]) == 0
    state, meta, extra = load_checkpoint(tmp_path / "checkpoint.h5")
    del meta["params"]["fbm"]["force"]
    save_checkpoint(tmp_path / "checkpoint.h5", state, meta, extra)
    assert main(["resume", str(tmp_path), "--quiet", "--no-plot"]) == 0
    with h5py.File(tmp_path / "run.h5") as f:
        assert f["t"][-1] == pytest.approx(0.03) and f["t"].shape == (7,)
    save_checkpoint(tmp_path / "checkpoint.h5", state, meta, extra)
    info = json.loads((tmp_path / "run.json").read_text())
    info["params"]["fbm"]["force"] = "test-function"
    (tmp_path / "run.json").write_text(json.dumps(info))
    assert main(["resume", str(tmp_path), "--quiet", "--no-plot"]) == 2
    assert "is for other parameters: params.fbm.force" in capsys.readouterr().err


def test_damaged_or_missing_run_data_and_a_bad_level_are_refused(tmp_path, capsys):
    """Resume trusts none of its files: a truncated or deleted ``run.h5`` and a level out of
    range in ``run.json`` exit 2 with one line (before: a traceback, or a run.h5 silently
    replaced by the rows after the checkpoint)."""
    _short_run(tmp_path)
    data = (tmp_path / "run.h5").read_bytes()
    (tmp_path / "run.h5").write_bytes(data[:len(data) // 3])
    assert main(["resume", str(tmp_path), "--quiet", "--no-plot"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot be read" in err[0]
    (tmp_path / "run.h5").unlink()
    assert main(["resume", str(tmp_path), "--quiet", "--no-plot"]) == 2
    assert "run.h5 is missing" in capsys.readouterr().err
    (tmp_path / "run.h5").write_bytes(data)
    info = json.loads((tmp_path / "run.json").read_text())
    (tmp_path / "run.json").write_text(json.dumps({**info, "level": 99}))
    assert main(["resume", str(tmp_path), "--quiet", "--no-plot"]) == 2
    assert "level must be an integer from 0 to" in capsys.readouterr().err


def test_an_interrupted_run_saves_its_step_and_resumes(tmp_path, capsys, monkeypatch):
    """Ctrl-C / SIGTERM stop the run after the step under way: a checkpoint of that step, one
    line naming it and the resume command, exit 128 + the signal; resume then finishes the run."""
    from fbmflow import interrupt

    before = signal.getsignal(signal.SIGTERM)
    with interrupt.handling(), interrupt.safe_point("step"):
        assert interrupt.requested() is None
        os.kill(os.getpid(), signal.SIGTERM)  # the handler only records it
        assert interrupt.requested() == signal.SIGTERM
    assert signal.getsignal(signal.SIGTERM) is before  # restored after the loop
    assert "SIGTERM: stopping after this step" in capsys.readouterr().err  # at once: a step can be long
    monkeypatch.setattr(interrupt, "requested", lambda: signal.SIGTERM)  # as if it came in step 1
    args = ["glowinski-free-fall", "--level", "0", "--set", "time.t_end=0.03", "--set", "time.dt=0.005",
            "--quiet", "--no-plot"]
    assert main(["run", *args, "--out", str(tmp_path)]) == 128 + signal.SIGTERM
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "interrupted at step 1" in err[0] and f"fbmflow resume {tmp_path}" in err[0]
    assert _checkpoint_step(tmp_path / "checkpoint.h5") == 1
    monkeypatch.undo()
    assert main(["resume", str(tmp_path), "--quiet", "--no-plot"]) == 0
    with h5py.File(tmp_path / "run.h5") as f:
        assert np.array_equal(f["step"][()], np.arange(7))


def _disk_simulation(t_end=0.08):
    """The README's settling disk, shorter and coarser."""
    import fbmflow as fb

    mesh = fb.StructuredMesh.box((8, 24), upper=(2.0, 6.0))
    disk = fb.Particles.at_rest([fb.Ball(0.125, dim=2)], density=1.25, position=[[1.0, 4.0]])
    return fb.Simulation(mesh, disk, fb.FluidParams(density=1.0, viscosity=0.1, gravity=980.0),
                         time=fb.TimeParams(dt=0.01, t_end=t_end, scheme="crank-nicolson"),
                         coupling=fb.CouplingParams(integrator="trapezoidal"))


def test_a_script_s_run_resumes_bit_exactly_from_its_folder(tmp_path):
    """``sim.run(out, checkpoint_every=3)`` stopped after step 5 (the checkpoint of step 3 is the
    last) and ``fbmflow.resume(out)`` end where the uninterrupted run ends, to the last bit, and
    ``run.h5`` holds each step once."""
    import fbmflow as fb

    whole = _disk_simulation()
    whole.run(tmp_path / "whole", checkpoint_every=3)

    def crash(report):
        if report.step == 5:
            raise RuntimeError("killed")

    with pytest.raises(RuntimeError, match="killed"):
        _disk_simulation().run(tmp_path / "stopped", checkpoint_every=3, callback=crash)
    assert _checkpoint_step(tmp_path / "stopped" / "checkpoint.h5") == 3
    resumed = fb.resume(tmp_path / "stopped")
    assert resumed.step_count == whole.step_count == 8
    assert np.array_equal(resumed.x, whole.x)
    assert np.array_equal(resumed.particles.velocity, whole.particles.velocity)
    with h5py.File(tmp_path / "stopped" / "run.h5") as f, h5py.File(tmp_path / "whole" / "run.h5") as g:
        assert np.array_equal(f["step"][()], np.arange(9))
        assert np.array_equal(f["velocity"][()], g["velocity"][()])


def test_a_script_s_run_without_a_stored_set_up_says_how_to_resume(tmp_path, caplog):
    """A set-up pickle cannot hold (a lambda as a boundary value): the run warns, and
    ``fbmflow.resume`` names the way that works, which then does."""
    import fbmflow as fb

    sim = _disk_simulation(0.03)
    sim._setup["boundary"] = {"unpicklable": lambda x: x}  # what a script's lambda would be
    with caplog.at_level("WARNING"):
        sim.run(tmp_path, checkpoint_every=1)
    assert "cannot be stored" in caplog.text
    with pytest.raises(fb.ParamError, match=r"call sim.run\(.*resume=True\)"):
        fb.resume(tmp_path)
    again = _disk_simulation(0.03)
    again.run(tmp_path, checkpoint_every=1, resume=True)
    assert again.step_count == 3


def test_a_resumed_run_estimates_its_error_as_the_run_was_asked_to(tmp_path, monkeypatch):
    """``--estimate-error`` is written to ``run.json``: a run interrupted before its end (the
    long case: hours at the finest level) resumes, finishes and then runs the coarser level,
    and its summary holds the estimate (a resume used to drop it)."""
    from fbmflow import interrupt

    monkeypatch.setattr(interrupt, "requested", lambda: signal.SIGTERM)  # as if it came in step 1
    args = ["glowinski-free-fall", "--level", "1", "--estimate-error", "--set", "time.t_end=0.03", "--set",
            "time.dt=0.005", "--quiet", "--no-plot"]
    assert main(["run", *args, "--out", str(tmp_path)]) == 128 + signal.SIGTERM
    assert json.loads((tmp_path / "run.json").read_text())["estimate_error"] is True
    monkeypatch.undo()
    assert main(["resume", str(tmp_path), "--quiet", "--no-plot"]) == 0
    estimate = json.loads((tmp_path / "summary.json").read_text())["error_estimate"]
    assert estimate["levels"] == [0, 1] and (tmp_path / "coarser" / "level-0" / "summary.json").is_file()
