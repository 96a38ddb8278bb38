"""Signals for every scene: a steady solve stops after its Newton iteration, a set-up at once, a
second signal aborts at once without a traceback, SIGHUP stops a time loop as SIGTERM does."""
import os
import signal
import subprocess
import sys
import time

import pytest

from fbmflow import interrupt
from fbmflow.cli import main


def test_a_signal_during_set_up_stops_at_once():
    """No safe point lies ahead: the handler interrupts where the set-up is."""
    with interrupt.handling():
        with pytest.raises(interrupt.StopRequested, match="SIGTERM: stopped during set-up") as stop:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1.0)  # the handler runs before this returns
    assert stop.value.exit_status == 128 + signal.SIGTERM


def test_a_steady_scene_stops_after_its_newton_iteration(tmp_path, capsys, monkeypatch):
    """The cavity printed "stopping after this step" and ran on to exit 0; now it stops after the
    Newton iteration under way (the signal sent as its Newton iteration starts), with exit 130."""
    check, sent = interrupt.check, []

    def signal_in_newton():
        if not sent:
            sent.append(os.kill(os.getpid(), signal.SIGINT))
        check()

    monkeypatch.setattr(interrupt, "check", signal_in_newton)
    code = main(["run", "cavity-2d", "--level", "2", "--quiet", "--no-plot", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 130, err
    assert "stopping after this Newton iteration" in err[0] and "stopped after a Newton iteration" in err[-1]
    assert not (tmp_path / "summary.json").exists()


def _cli(*args):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "fbmflow.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


def _wait_for(path, proc, timeout=240.0):
    deadline = time.time() + timeout
    while not path.exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, proc.stderr.read()


@pytest.mark.slow
def test_sighup_stops_a_time_loop_with_a_checkpoint_and_a_second_signal_aborts_cleanly(tmp_path):
    run = ["run", "glowinski-free-fall", "--level", "1", "--set", "time.t_end=1.0", "--checkpoint-every", "2",
           "--quiet", "--no-plot"]
    hup = _cli(*run, "--out", str(tmp_path / "hup"))
    _wait_for(tmp_path / "hup" / "checkpoint.h5", hup)
    hup.send_signal(signal.SIGHUP)
    assert hup.wait(120) == 128 + signal.SIGHUP
    err = hup.stderr.read().strip().splitlines()
    assert "interrupted at step" in err[-1] and "Traceback" not in "\n".join(err)
    twice = _cli(*[a if a != "1" else "2" for a in run], "--out", str(tmp_path / "twice"))  # level 2:
    _wait_for(tmp_path / "twice" / "checkpoint.h5", twice)  # steps long enough to signal twice in one
    twice.send_signal(signal.SIGINT)
    time.sleep(0.05)
    twice.send_signal(signal.SIGINT)
    code = twice.wait(120)
    err = twice.stderr.read()
    assert code == 130 and "Traceback" not in err and "SystemError" not in err, err
    assert "aborted at once" in err.strip().splitlines()[-1]
    assert (tmp_path / "twice" / "checkpoint.h5").is_file()
