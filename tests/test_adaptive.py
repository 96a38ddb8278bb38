"""Adaptive time stepping (:mod:`fbmflow.adaptive`): the tolerance controls the error, a failed
solve is taken again shorter, the Courant cap holds, the run lands on ``t_end``, and a resumed
run takes the same steps; on a simulation: refusals and a bit-exact resume."""
import json
import types

import numpy as np
import pytest

from fbmflow.adaptive import StepControl
from fbmflow.cli import main
from fbmflow.params import TimeParams
from fbmflow.particles import Ball, Particles
from fbmflow.solvers import ConvergenceError

TAU, U, H = 0.2, 1.0, 0.1  # relaxation time [s], terminal speed, cell size


class Relaxing:
    """A stand-in for a Simulation: one disk whose velocity relaxes to ``U`` downwards,
    ``u' = (U - u) / tau``, by backward Euler (first order, like the coupled scheme's particles),
    on cells of side ``H``; ``fail_above``: a step longer than that fails to converge; from
    ``kick_at`` on, the terminal speed is ``3 U`` (a sudden push)."""

    def __init__(self, fail_above=np.inf, kick_at=np.inf):
        self.particles = Particles.at_rest([Ball(0.05, dim=2)], 2.0, [[0.5, 5.0]])
        self.mesh = types.SimpleNamespace(cell_size_at=lambda p: np.full(np.shape(p), H))
        self.t, self.fail_above, self.kick_at, self.steps = 0.0, fail_above, kick_at, []

    def step(self, dt):
        if dt > self.fail_above:
            raise ConvergenceError("no convergence")
        p = self.particles
        target = 3 * U if self.t >= self.kick_at else U
        v = (p.velocity[0, 1] - dt * target / TAU) / (1.0 + dt / TAU)
        p.position[0, 1] += 0.5 * dt * (p.velocity[0, 1] + v)
        p.velocity[0, 1] = v
        self.t += dt
        self.steps.append(dt)
        return dt

    def state(self):
        return {"t": self.t, "velocity": self.particles.velocity.copy(),
                "position": self.particles.position.copy(), "steps": list(self.steps)}

    def set_state(self, state):
        self.t, self.steps = state["t"], list(state["steps"])
        self.particles.velocity, self.particles.position = state["velocity"].copy(), state["position"].copy()


def _exact_speed(t):
    return U * (1.0 - np.exp(-t / TAU))


def _run(control, sim, until=None):
    while not control.finished(sim.t) and (until is None or len(sim.steps) < until):
        control.step(sim)
    return sim


def _time(tolerance, max_courant=10.0, dt=0.001, t_end=0.5):
    return TimeParams(dt=dt, t_end=t_end, adaptive=True, tolerance=tolerance, max_courant=max_courant)


def test_the_tolerance_controls_the_error_and_the_run_lands_on_t_end():
    """Each decade of tolerance cuts the error at t_end about sqrt(10) times (first-order steps
    sized by a second-order estimate) for about sqrt(10) times the steps; the last step lands on
    t_end."""
    errors, steps = [], []
    for tol in (1e-2, 1e-3, 1e-4):
        sim = Relaxing()
        control = StepControl(_time(tol), sim.particles)
        _run(control, sim)
        assert sim.t == pytest.approx(0.5, abs=1e-12)
        assert control.smallest == min(sim.steps) and control.largest == max(sim.steps)
        errors.append(abs(-sim.particles.velocity[0, 1] - _exact_speed(sim.t)))
        steps.append(len(sim.steps))
    assert errors[1] < errors[0] / 2 and errors[2] < errors[1] / 2, errors
    assert steps[0] < steps[1] < steps[2], steps
    assert max(sim.steps) > 3 * min(sim.steps)  # the steps grow as the acceleration decays


def test_a_sudden_push_rejects_steps_and_shortens_them():
    sim = Relaxing(kick_at=0.3)
    control = StepControl(_time(1e-3), sim.particles)
    _run(control, sim)
    t = np.cumsum([0.0] + sim.steps[:-1])  # each step's start
    before, after = np.array(sim.steps)[t < 0.3], np.array(sim.steps)[t >= 0.3]
    assert control.rejected > 0
    assert after[:3].min() < before[-1] / 2
    assert control.error(np.zeros((1, 3)), 0.01, H) > 0  # (it has a history now)


def test_a_failed_solve_is_taken_again_at_a_quarter_and_a_hopeless_one_stops():
    sim = Relaxing(fail_above=0.004)
    control = StepControl(_time(1e-2, dt=0.01), sim.particles)
    _run(control, sim)
    assert control.rejected >= 1 and max(sim.steps) <= 0.004
    sim = Relaxing(fail_above=0.0)
    with pytest.raises(ConvergenceError, match="cannot shrink further") as err:
        _run(StepControl(_time(1e-2), sim.particles), sim)
    assert err.value.remedy


def test_a_failure_no_shorter_step_helps_is_not_retried():
    """A ConvergenceError whose ``retry`` is False (the GPU's memory ran out, say) stops the step at
    once: no shorter step is tried."""

    class OutOfMemory(ConvergenceError):
        retry = False

    sim = Relaxing()
    sim.step = lambda dt: (_ for _ in ()).throw(OutOfMemory("out of memory", "use less"))
    control = StepControl(_time(1e-2, dt=0.01), sim.particles)
    with pytest.raises(OutOfMemory, match="out of memory"):
        control.step(sim)
    assert control.rejected == 0 and control.dt == 0.01


def test_the_courant_cap_holds():
    sim = Relaxing()
    control = StepControl(_time(1.0, max_courant=0.5, dt=0.01), sim.particles)
    speeds = []
    while not control.finished(sim.t):
        speeds.append(-sim.particles.velocity[0, 1])
        control.step(sim)
    for dt, speed in zip(sim.steps[1:-1], speeds[1:-1]):
        assert speed * dt / H <= 0.5 * (1 + 1e-12)
    assert max(s * dt / H for dt, s in zip(sim.steps[1:-1], speeds[1:-1])) > 0.45


def test_a_restored_controller_takes_the_same_steps():
    whole = Relaxing()
    _run(StepControl(_time(1e-3), whole.particles), whole)
    first = Relaxing()
    control = StepControl(_time(1e-3), first.particles)
    _run(control, first, until=7)
    saved = {**first.state(), **control.state(), "step_count": 7}
    again = Relaxing()
    again.set_state(saved)
    restored = StepControl(_time(1e-3), again.particles)
    restored.set_state(saved)
    _run(restored, again)
    assert again.steps == whole.steps
    with pytest.raises(ValueError, match="time.adaptive = false"):
        StepControl(_time(1e-3), again.particles).set_state({"step_count": 3})


def test_adaptive_steps_are_refused_with_contact_without_free_particles_and_without_particles(capsys):
    p = Particles.at_rest([Ball(0.05, dim=2)], 2.0, [[0.5, 5.0]])
    with pytest.raises(ValueError, match="contact impulses"):
        StepControl(_time(1e-3), p, contact=True)
    p.fixed[:] = True
    with pytest.raises(ValueError, match="no free particle"):
        StepControl(_time(1e-3), p)
    assert main(["run", "taylor-green-2d", "--level", "0", "--set", "time.adaptive=true", "--quiet",
                 "--no-plot"]) == 2
    assert "time.adaptive = false" in capsys.readouterr().err


def _disk(adaptive=True, force="auto"):
    import fbmflow as fb

    mesh = fb.StructuredMesh.box((8, 24), upper=(2.0, 6.0))
    disk = fb.Particles.at_rest([fb.Ball(0.125, dim=2)], density=1.25, position=[[1.0, 4.0]])
    return fb.Simulation(mesh, disk, fb.FluidParams(density=1.0, viscosity=0.1, gravity=980.0),
                         time=fb.TimeParams(dt=0.005, t_end=0.1, scheme="crank-nicolson", adaptive=adaptive,
                                            tolerance=2e-3),
                         coupling=fb.CouplingParams(integrator="trapezoidal"),
                         fbm=fb.FictitiousBoundaryParams(force=force))


def test_with_varying_steps_the_trapezoidal_rule_takes_each_steps_own_pressure_force(caplog):
    """Adaptive steps with Crank–Nicolson: the new velocity is ``v + dt/2 (a_visc^n + a_visc^{n+1})
    + dt a_p^{n+1}`` (the midpoint rule for the step's pressure), not the mean of two steps'
    pressure forces; fixed steps keep that mean. A force that cannot separate the pressure warns."""
    fixed, sim = _disk(adaptive=False), _disk()
    assert sim.system.midpoint_pressure and not fixed.system.midpoint_pressure
    sim.step(0.004)
    system, dt = sim.system, 0.006
    p = system.particles
    solved = sim.coupling.advance(system, dt)
    new = system.integrate(solved.force, solved.torque, dt, x=solved.x)
    pressure = system.pressure_forces(solved.x, dt)[0]
    viscous = 0.5 * (system.last_force - system.last_pressure[0] + solved.force - pressure)
    weight = (1.0 - 1.0 / 1.25) * system.gravity
    expected = p.velocity + dt * ((viscous + pressure) / p.mass[:, None] + weight)
    assert np.allclose(new.velocity, expected, rtol=1e-12, atol=1e-12)
    mean = p.velocity + dt * (0.5 * (system.last_force + solved.force) / p.mass[:, None] + weight)
    assert not np.allclose(new.velocity, mean, rtol=1e-6)  # the pairing made a difference
    with pytest.raises(ValueError, match="needs the step's flow"):
        system.integrate(solved.force, solved.torque, dt)
    assert not _disk(force="test-function").system.midpoint_pressure
    assert "does not separate the pressure" in caplog.text


def test_an_adaptive_simulation_resumes_bit_exactly(tmp_path):
    """A run of adaptive steps stopped after step 5 (checkpoint at step 3) and resumed ends
    where the uninterrupted run ends, to the last bit, with the same steps."""
    import fbmflow as fb

    whole = _disk()
    reports = whole.run(tmp_path / "whole", checkpoint_every=3)
    assert whole.t == pytest.approx(0.1, abs=1e-12)
    steps = np.diff([0.0] + [r.t for r in reports])
    assert steps.max() > 1.5 * steps.min()  # the steps did adapt

    def crash(report):
        if report.step == 5:
            raise RuntimeError("killed")

    with pytest.raises(RuntimeError, match="killed"):
        _disk().run(tmp_path / "stopped", checkpoint_every=3, callback=crash)
    resumed = fb.resume(tmp_path / "stopped")
    assert resumed.step_count == whole.step_count
    assert np.array_equal(resumed.x, whole.x)
    assert np.array_equal(resumed.particles.velocity, whole.particles.velocity)
    assert resumed.control.rejected == whole.control.rejected


def test_a_scene_reports_its_adaptive_steps(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "glowinski-free-fall", "--level", "0", "--set", "time.adaptive=true", "--set",
                 "time.t_end=0.05", "--quiet", "--no-plot", "--out", str(out)]) == 0
    q = json.loads((out / "summary.json").read_text())["quantities"]
    assert 0 < q["time_step_smallest"] <= q["time_step"] <= q["time_step_largest"]
    assert q["rejected_steps"] >= 0 and q["courant_number"] > 0
