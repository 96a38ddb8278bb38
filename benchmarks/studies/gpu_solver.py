"""The GPU solver (solver.device = "gpu"): its sweep order on the CPU, its device memory, and on a GPU its
seconds per cycle and per step.

Question: the GPU sweeps the factored Vanka smoother's patches in colours (a colour's patches at
once) instead of the CPU's slabs; does that order take more multigrid cycles per solve, and how
much device memory does the GPU solver hold per unknown? On a GPU: how fast is a step against the
CPU path of the same machine?
Answer: no more cycles: on the CPU in the GPU's colour order ten Cate level 1 takes 3.00 cycles per
solve as in slab order, glowinski-free-fall level 3 10.93 against 10.79. The GPU solver holds 1 646
bytes per unknown on the device in 3D (ten Cate level 1: 1 158 the hierarchy with the copies it
keeps across set-ups and a Newton block's coefficients, 488 FGMRES's basis; level 2 1 599) and 992
in 2D (glowinski level 3), its smoothers reading the velocity rows and the divergence from the
operators' copies, its transfers held as scalar blocks (1 813 and 1 084 before those two, 2 050 and
1 174 with the smoothers' own copies). The speed on a GPU is not measured yet (no GPU was lent);
the GPU takes over the cycles and the smoothers' local factors, and on this machine the rest of
the set-up and the work outside the solves are 5.27 + 14.06 s of a 90.88 s ten Cate level-2 step,
of which the factors are 64 % of the set-up (4.16 of 6.54 s): free cycles and factors would make it at
most about 5.7x faster (4.70x with the factors on the CPU; level 1: 5.2x and 4.40x). Timed
apart (the arrays row's column), the CPU keeps 4.11 s of a level-2 step (steps 2-5, mean) after
the changes of 2026-12-01, 5.34 s before them, on one machine alone (3.66 s on a faster one),
about two thirds of it serial; the copies to the device are 532 bytes per unknown per step.
(The rows host-L2 and host-L2-cut ran beside another job: their figures are overstated.)
Measured: 2026-11-30, commit ce687a0 (order), 5561688 (bytes, with the blocks on the device as on the
CPU), e1a47de (split), 5f0607f (split-factors) and the rows shared after 85226ef
(bytes-rows-shared); 2026-12-01, the copies kept across set-ups (kept, kept-L2, kept-2d), the CPU's
share (host-L2 at 1a8e9f4, host-L2-cut, host-L1-threads1/2, host-L2-copies, host-L2-kept);
2026-12-02, the CPU's share before and after one machine alone (base-L2 at 1a8e9f4, now-L2); quoted
in docs/validation/gpu.md, "Device memory" and "What the GPU path keeps on the CPU at level 2"
Run: python -m fbmbench gpu_solver --rows slabs colours arrays (on a GPU: benchmarks/device/gpu.sh)

Rows, each in a process of its own, one after the other, ``steps`` time steps of the scene at its
defaults with multigrid (``solver.linear = multigrid``):

* ``slabs``: the CPU, the smoothers in slab order (the default);
* ``colours``: the CPU, the smoothers in the GPU's colour order (``solver.multigrid.order``): the
  GPU's arithmetic, so its cycles are the GPU's;
* ``arrays``: the GPU solver set up with NumPy arrays in place of CuPy's (no GPU needed: the
  arrays a device would hold, the same sizes) and its solves done by the CPU hierarchy it was
  built from: the device memory per unknown, the hierarchy's (operators, smoothers, transfers)
  and FGMRES's basis; and the seconds per step left on the CPU, the step less the work a GPU
  does (the solves, the flow problem's residuals, the smoothers' factors and a moved Newton
  block's coefficients, timed; the copy of the factors, which a GPU computes where they stay,
  counts as the CPU's) and less the copies to the device (timed and counted apart: NumPy's copies
  of fresh memory here, a transfer on a GPU, whose speed is the ``gpu`` row's);
* ``gpu``: ``solver.device = gpu`` (a machine with a GPU and the ``gpu`` extra), counting the GPU
  kernels' launches per step and the host's seconds in them (numba-cuda prepares a launch's
  arguments on the host: where those seconds approach the cycles', the cycles are bound by the
  launches, not by the GPU). A smoother's sweep, and the Newton term's product, is one cooperative
  launch (its colours in turn, the grid synchronised between them);
* ``gpu-colours``: as ``gpu``, but those kernels launch once per colour (a sweep: 27 in 3D, and the
  interface's): the launches' cost, against the ``gpu`` row.

Cycles: FGMRES iterations, one cycle each; per solve: over all the step's linear solves. The
step's seconds split into the linear solves' cycles (FGMRES with its cycles), the set-up of their
hierarchies (smoothers' factors, timed apart, which the GPU solver computes on the device; the
rest of the smoothers' set-up and the coarsest factorisation, which it does on the CPU before
copying) and the rest outside the solves (assembling the levels' systems, residuals, forces,
coupling); a solver that made the cycles free would make the step ``step / (set-up + rest)``
times faster at most, one that made the factors free as well ``step / (set-up - factors + rest)``:
the bounds on the GPU's speed-up.

writes benchmarks/results/gpu_solver.{json,md}; ``--tag`` names the run (rows with other tags are
kept).
"""
from __future__ import annotations

import cProfile
import io
import json
import pstats
import resource
import subprocess
import sys
import time
import types
from pathlib import Path

from studies.thread_scaling import BENCHMARKS, RESULTS, commit, machine

#: the profiler of :func:`_profile_step` while it runs (the arrays row leaves the GPU's work out of it)
_PROFILER: cProfile.Profile | None = None

ROWS = {"slabs": ["solver.multigrid.order=slabs"], "colours": ["solver.multigrid.order=colours"],
        "arrays": ["solver.multigrid.order=colours"], "gpu": ["solver.device=gpu"],
        "gpu-colours": ["solver.device=gpu"]}


def _count_device_arrays(record: dict) -> None:
    """Make ``solver.device = gpu`` build its device hierarchy from NumPy arrays (the simulator's
    backend; the smoothers' factors and a Newton block's coefficients computed by the CPU's
    kernels, as many bytes) and solve on the CPU
    hierarchy under it, its residuals' products (the velocity operator, the gradient and the
    continuity rows) on the CPU too, timed as the GPU's work, recording the device bytes per unknown
    (the space's cells, which the residuals share with the Newton terms, counted once)."""
    import fbmflow.gpu.multigrid as gm
    import fbmflow.gpu.operator as go
    from fbmflow.fem import _kernels as cpu
    from fbmflow.gpu.device import Backend, simulated_backend
    from fbmflow.solvers import _kernels as vanka_kernels
    from fbmflow.solvers.base import LinearSolver

    record["device_work_s"] = record["copy_s"] = record["copy_bytes"] = 0.0
    depth = [0]  # how many timed calls are under way: one inside another counts as the outer one

    def device_work(work, key="device_work_s"):
        """``work`` timed as the GPU's (``key``: or as the copies to it), out of a profile of the
        step (:func:`_profile_step`); within another such call, part of that one's time."""
        def timed(*args, **kwargs):
            if depth[0]:
                return work(*args, **kwargs)
            depth[0] += 1
            if _PROFILER is not None:
                _PROFILER.disable()
            t0 = time.perf_counter()
            try:
                return work(*args, **kwargs)
            finally:
                record[key] += time.perf_counter() - t0
                depth[0] -= 1
                if _PROFILER is not None:
                    _PROFILER.enable()
        return timed

    copy = device_work(Backend.put, "copy_s")

    def put(self, a, dtype=None):
        """A copy to the device (on a GPU a transfer, not the CPU's work): a set-up's, counted,
        or within a solve, part of the solve's time."""
        outside = not depth[0]
        out = copy(self, a, dtype)
        record["copy_bytes"] += out.nbytes if outside else 0
        return out

    def react(u, cell_dofs, phi, dphi, detJw, Jinv, out, threads):  # the CPU's kernel, no GPU here
        out[...] = cpu.reaction_coefficients(u, cell_dofs, phi, dphi, detJw, Jinv)

    def drift(u, cell_dofs, phi, detJw, out, threads):
        out[...] = cpu.velocity_coefficients(u, cell_dofs, phi, detJw)

    go.reaction_coefficients, go.velocity_coefficients = device_work(react), device_work(drift)
    gm.gpu_problem = lambda: None

    def backend():
        made = simulated_backend()
        made.put = types.MethodType(put, made)
        return made

    gm.gpu_backend = backend
    gm.DeviceMultigridSolver.host_factors = True
    gm.DeviceMultigridSolver.velocity_operator = (
        lambda self, space: device_work(LinearSolver.velocity_operator(self, space)))

    def divergence_products(self, space, BT):  # the CPU's products, timed as the GPU's
        products = LinearSolver.divergence_products(self, space, BT)
        products.gradient = device_work(products.gradient)
        products.continuity = device_work(products.continuity)
        return products

    gm.DeviceMultigridSolver.divergence_products = divergence_products
    vanka_kernels.vanka_factor = device_work(vanka_kernels.vanka_factor)

    def solve(self, f, g, rtol=None):
        n = self.host.system.n_u + self.host.system.n_p
        record["hierarchy_bytes"] = max(record.get("hierarchy_bytes", 0.0), self.nbytes / n)
        krylov = 2 * self.settings.restart + 1  # FGMRES's V and Z
        record["krylov_bytes"] = 8.0 * krylov
        return self.host.solve(f, g, rtol)

    gm.DeviceHierarchy.solve = device_work(solve)


def measure(scene_name: str, level: int, row: str, steps: int, profile: Path | None = None) -> dict:
    """``steps`` steps of ``scene_name`` at ``level`` in this process, as row ``row`` says;
    ``profile``: a file for the cProfile of one more step, not in the record (its functions by own
    and by cumulative time)."""
    from fbmflow.scenes.registry import load_scene

    record: dict = {}
    settings = ["solver.linear=multigrid"] + ROWS[row]
    if row == "arrays":
        settings = ["solver.linear=multigrid", "solver.device=gpu"]
        _count_device_arrays(record)
    counts = None
    if row.startswith("gpu"):
        from fbmflow.gpu import colours
        from fbmflow.gpu.launches import count_launches

        counts = count_launches()
        colours.ONE_LAUNCH = row == "gpu"
    scene, params, level = load_scene(scene_name, level, settings)
    setup = scene.build(params, level)
    sim = setup.sim
    hierarchy = [0.0, 0.0]  # the step's set-up and factors' seconds, charged to the hierarchies' first solves

    def count_setup(report, system):
        hierarchy[0] += report.setup_time_s
        hierarchy[1] += report.factor_time_s

    sim.flow.on_linear_solve = count_setup
    out = []
    for _ in range(steps):
        hierarchy[0] = hierarchy[1] = 0.0
        if "device_work_s" in record:
            record["device_work_s"] = record["copy_s"] = record["copy_bytes"] = 0.0
        before = dict(counts) if counts else None
        t0 = time.perf_counter()
        rep = sim.step(setup.dt)
        out.append(dict(wall_s=time.perf_counter() - t0, solves=rep.linear.solves,
                        cycles=rep.linear.iterations, linear_s=rep.linear.time_s, setup_s=hierarchy[0],
                        factors_s=hierarchy[1]))
        if "device_work_s" in record:  # the step less what the GPU would do and the copies to it
            out[-1]["host_s"] = out[-1]["wall_s"] - record["device_work_s"] - record["copy_s"]
            out[-1].update(copy_s=record["copy_s"], copy_bytes=record["copy_bytes"])
        if counts:
            out[-1].update({key: counts[key] - before[key] for key in counts})
    velocity = sim.particles.velocity
    if profile:
        _profile_step(sim, setup.dt, profile, f"{scene_name} level {level}, row {row}: step {steps + 1}",
                      record)
    for key in ("device_work_s", "copy_s", "copy_bytes"):
        record.pop(key, None)
    return dict(scene=scene_name, level=level, row=row, unknowns=sim.flow.n_dofs, steps=out,
                particle_velocity=[float(v) for v in velocity[0]] if len(velocity) else [],
                solver=sim.flow.linear_solver_description,
                peak_rss_gb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9, **record)


def _profile_step(sim, dt: float, path: Path, title: str, record: dict) -> None:
    """One step of ``sim`` under cProfile: its functions by own and by cumulative time into
    ``path``; in the arrays row without the work a GPU does (its seconds in the title)."""
    global _PROFILER
    profiler = _PROFILER = cProfile.Profile()
    record["device_work_s"] = record["copy_s"] = 0.0
    t0 = time.perf_counter()
    profiler.enable()
    sim.step(dt)
    profiler.disable()
    _PROFILER = None
    wall = time.perf_counter() - t0
    text = io.StringIO()
    text.write(f"{title}, {wall:.2f} s under cProfile")
    if record["device_work_s"]:
        left = wall - record["device_work_s"] - record["copy_s"]
        text.write(f", {record['device_work_s']:.2f} s of it the GPU's work (solves, residuals, factors, "
                   f"coefficients) and {record['copy_s']:.2f} s the copies to it, not profiled: "
                   f"{left:.2f} s left on the CPU")
    text.write("\n")
    for order in ("tottime", "cumulative"):
        pstats.Stats(profiler, stream=text).sort_stats(order).print_stats(40)
    path.write_text(text.getvalue())


def table(rows: list[dict]) -> str:
    lines = ["# The GPU solver: sweep order, device memory, speed (python -m fbmbench gpu_solver)", "",
             "Each row a process of its own, the scene's defaults with multigrid. Cycles: FGMRES iterations "
             "(one cycle each) per linear solve, over the steps after the first (the first includes the "
             "set-up and JIT compilation). Device bytes: per unknown of the finest level, the hierarchy's "
             "arrays (operators, smoothers' factors and colours, transfers; the coarsest level stays on the "
             "CPU) and FGMRES's basis (2 x 30 + 1 vectors). Seconds compare only rows run alone on one "
             "machine: the rows tagged order-bytes, bytes-shared, host-L2 and host-L2-cut ran beside "
             "another job. A row's command, in benchmarks/ at the commit measured: `python -m fbmbench "
             "gpu_solver --scenes SCENE --levels LEVEL --rows ROW --steps STEPS --tag TAG` (STEPS: the "
             "steps column; base-L2 ran with the study file of now-L2; now-L2-rows-1thread with "
             "NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 before it).", "",
             "| scene | level | unknowns | row | solver | steps | s per step | cycles per solve "
             "| s per cycle | s per step in cycles / set-up (of it the smoothers' factors) "
             "/ outside the solves | bound on a faster solver's speed-up: set-up on the CPU / factors not "
             "| s per step left on the CPU (arrays: the step less its solves, residuals, factors and "
             "Newton coefficients, and its copies to the device where the next column gives them) "
             "| copies to the device per step: bytes per unknown (s as NumPy copies) "
             "| device bytes per unknown (hierarchy + basis) "
             "| GPU kernel launches per step (host s in them) "
             "| particle 0's vertical velocity after the steps | peak host GB | machine | measured | tag |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        later = r["steps"][1:] or r["steps"]
        step_s = sum(s["wall_s"] for s in later) / len(later)
        solves = sum(s["solves"] for s in later)
        cycles = sum(s["cycles"] for s in later)
        linear_s = sum(s["linear_s"] for s in later)
        device = (f"{r['hierarchy_bytes'] + r['krylov_bytes']:.0f} ({r['hierarchy_bytes']:.0f} + "
                  f"{r['krylov_bytes']:.0f})" if "hierarchy_bytes" in r else "–")
        split, bound = "–", "–"
        if all("setup_s" in s for s in later):
            setup_s = sum(s["setup_s"] for s in later) / len(later)
            cycles_s = linear_s / len(later) - setup_s
            split = f"{cycles_s:.2f} / {setup_s:.2f} / {step_s - cycles_s - setup_s:.2f}"
            bound = f"{step_s / (step_s - cycles_s):.2f}"
            if all("factors_s" in s for s in later):
                factors_s = sum(s["factors_s"] for s in later) / len(later)
                split = (f"{cycles_s:.2f} / {setup_s:.2f} (factors {factors_s:.2f}) / "
                         f"{step_s - cycles_s - setup_s:.2f}")
                bound += f" / {step_s / (step_s - cycles_s - factors_s):.2f}"
        host = (f"{sum(s['host_s'] for s in later) / len(later):.2f}"
                if all("host_s" in s for s in later) else "–")
        copies = "–"
        if all("copy_bytes" in s for s in later):
            copies = (f"{sum(s['copy_bytes'] for s in later) / len(later) / r['unknowns']:.0f} "
                      f"({sum(s['copy_s'] for s in later) / len(later):.2f})")
        cycle_s = (linear_s - sum(s.get("setup_s", 0.0) for s in later)) / max(cycles, 1)
        vertical = f"{r['particle_velocity'][-1]:.9g}" if r.get("particle_velocity") else "–"
        launches = "–"
        if "launches" in later[0]:
            launches = (f"{sum(s['launches'] for s in later) / len(later):.0f} "
                        f"({sum(s['launch_s'] for s in later) / len(later):.2f})")
        lines.append(f"| {r['scene']} | {r['level']} | {r['unknowns']} | {r['row']} | {r['solver']} | "
                     f"{len(r['steps'])} | {step_s:.2f} | {cycles / max(solves, 1):.2f} | {cycle_s:.3f} | "
                     f"{split} | {bound} | {host} | {copies} | {device} | {launches} | {vertical} | "
                     f"{r['peak_rss_gb']:.2f} | {r['machine']} | "
                     f"{r['measured']} | {r['tag']} |")
    return "\n".join(lines) + "\n"


def run(*, scenes: list[str] = ("ten-cate", "glowinski-free-fall"), levels: list[int] = (1, 3),
        rows: list[str] = ("slabs", "colours", "arrays"), steps: int = 3, tag: str = "",
        profile: list[str] = (), one: list[str] = ()) -> None:
    """Every scene (at the level in the same place of ``levels``) with every row, each in a
    process of its own.

    Parameters
    ----------
    scenes : scenes to run
    levels : their levels, one per scene
    rows : slabs, colours, arrays, gpu, gpu-colours (see the module docstring)
    steps : time steps per row
    tag : names this run's rows in the results
    profile : rows that run one more step under cProfile, not in the record: its functions by own
        and by cumulative time in benchmarks/results/gpu_solver.profile-TAG-SCENE-LEVEL-ROW.txt
    one : internal: run SCENE LEVEL ROW in this process
    """
    if one:
        where = RESULTS / f"gpu_solver.profile-{tag}-{one[0]}-{one[1]}-{one[2]}.txt"
        print(json.dumps(measure(one[0], int(one[1]), one[2], steps, where if one[2] in profile else None)))
        return
    path = RESULTS / "gpu_solver.json"
    kept = [r for r in json.loads(path.read_text()) if r["tag"] != tag] if path.exists() else []
    stamp = f"{time.strftime('%Y-%m-%d')} {commit()}"
    for scene, level in zip(scenes, levels):
        for row in rows:
            command = ["gpu_solver", "--steps", str(steps), "--tag", tag, "--one", scene, str(level), row]
            command += [f"--profile={name}" for name in profile]
            done = subprocess.run([sys.executable, "-m", "fbmbench", *command], capture_output=True,
                                  text=True, cwd=BENCHMARKS)
            if done.returncode != 0:  # say why, and go on with the other rows (a device session is short)
                print(f"{scene} level {level} row {row} failed (exit {done.returncode}):\n"
                      f"{done.stdout[-2000:]}{done.stderr[-4000:]}", flush=True)
                continue
            result = json.loads(done.stdout.strip().splitlines()[-1])
            result.update(machine=machine(), measured=stamp, tag=tag)
            kept.append(result)
            print(json.dumps(result), flush=True)
            path.write_text(json.dumps(kept, indent=1))
            (RESULTS / "gpu_solver.md").write_text(table(kept))
