"""One owner per output folder, results never replaced without a word, resume only from the run's
own files, and OS errors as one line naming the file."""
import json
import os
import shutil
import socket
from collections import namedtuple

import h5py
import numpy as np
import pytest

from fbmflow.cli import main
from fbmflow.config import ParamError
from fbmflow.run import LOCK, claim
from fbmflow.scenes.registry import finite

SHORT = ["glowinski-free-fall", "--level", "0", "--set", "time.t_end=0.02", "--set", "time.dt=0.005",
         "--checkpoint-every", "2", "--quiet", "--no-plot"]


def test_a_folder_being_written_is_refused_and_a_stale_lock_taken_over(tmp_path, capsys):
    (tmp_path / LOCK).write_text(json.dumps({"pid": os.getppid(), "host": socket.gethostname(),
                                             "since": "2026-11-28 00:00:00"}))
    assert main(["run", *SHORT, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"is being written by process {os.getppid()}" in err[0], err
    (tmp_path / LOCK).write_text(json.dumps({"pid": 2**22 + 12345, "host": socket.gethostname()}))  # gone
    assert main(["run", *SHORT, "--out", str(tmp_path)]) == 0
    assert not (tmp_path / LOCK).exists()  # released at the end


def test_a_finished_run_is_replaced_only_with_overwrite(tmp_path, capsys):
    assert main(["run", *SHORT, "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    assert main(["run", *SHORT, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds another run's results" in err[0] and "--overwrite" in err[0], err
    (tmp_path / "notes.txt").write_text("mine")
    assert main(["run", *SHORT, "--set", "time.t_end=0.01", "--out", str(tmp_path), "--overwrite"]) == 0
    with h5py.File(tmp_path / "run.h5") as f:
        assert f["step"].shape == (3,)  # the new run's rows only
    assert (tmp_path / "notes.txt").read_text() == "mine"  # not a run's file: kept


def test_resume_refuses_another_run_s_data(tmp_path, capsys):
    """A ``run.h5`` from another scene, or one cut short of the checkpoint, is named and refused
    (before: accepted, the resumed rows appended to it)."""
    assert main(["run", *SHORT, "--out", str(tmp_path / "a")]) == 0
    assert main(["run", "sedimentation-2d", "--level", "0", "--set", "particles.count=4", "--set",
                 "time.t_end=0.01", "--set", "time.dt=0.005", "--quiet", "--no-plot", "--out",
                 str(tmp_path / "b")]) == 0
    capsys.readouterr()
    shutil.copy(tmp_path / "b" / "run.h5", tmp_path / "a" / "run.h5")
    assert main(["resume", str(tmp_path / "a"), "--quiet", "--no-plot"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "belongs to another run: scene is 'sedimentation-2d' there" in err[0], err


def test_a_file_that_cannot_be_written_is_one_line_and_the_checkpoint_is_kept(tmp_path, capsys, monkeypatch):
    """A full disk: exit 1 and one line naming the file and the last checkpoint (the run would
    have gone on writing into a full disk: h5py tracebacks, and with field output a crash)."""
    import fbmflow.run as run

    Usage = namedtuple("Usage", "total used free")
    real, calls = shutil.disk_usage, []

    def filling(path):  # room for the first checkpoint, none for the second
        calls.append(path)
        return Usage(1e12, 1e12, 1e12 if len(calls) < 2 else 1e3)

    monkeypatch.setattr(run.shutil, "disk_usage", filling)
    assert main(["run", *SHORT, "--set", "time.t_end=0.05", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "checkpoint.h5: the disk holding" in err[0] and "is full" in err[0], err
    assert "the last checkpoint (step 2)" in err[0] and f"fbmflow resume {tmp_path}" in err[0]
    monkeypatch.setattr(run.shutil, "disk_usage", real)
    assert main(["resume", str(tmp_path), "--quiet", "--no-plot"]) == 0


def test_a_directory_where_run_h5_belongs_and_an_over_long_name_are_one_line(tmp_path, capsys):
    (tmp_path / "run.h5").mkdir()
    assert main(["run", *SHORT, "--out", str(tmp_path), "--overwrite"]) in (1, 2)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "run.h5" in err[0] and "Traceback" not in err[0], err
    assert main(["run", *SHORT, "--out", str(tmp_path / ("x" * 300))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "output directory" in err[0], err


def test_quantities_that_could_not_be_computed_are_null():
    q = finite({"a": float("nan"), "b": [1.0, float("inf")], "c": complex(0, 1), "d": np.float64(2.0)})
    assert json.dumps(q, allow_nan=False) == '{"a": null, "b": [1.0, null], "c": null, "d": 2.0}'


def test_claim_is_the_api_s_too(tmp_path):
    with claim(tmp_path):
        with pytest.raises(ParamError, match="is being written by process"):
            with claim(tmp_path):
                pass
    with claim(tmp_path):  # released
        pass
