"""Contact without fluid: time per step of broadphase + narrowphase + PGS for a settled pile of
spheres in a box, against pybullet on the same scene when it is installed.

Question: how does the contact solver's time per step grow with the number of spheres, and how
does it compare with pybullet on the same pile?
Answer: 9.1 ms for 10^3 spheres, 82 ms for 10^4 and 0.95 s for 10^5 (N^1.01, about 9 µs per
sphere, no overlap); pybullet 3.2.7: 113 ms and 3.2 s for 10^3 and 10^4 (N^1.44)
(benchmarks/results/contact.md).
Measured: 2026-11-21, commit e4b7968; quoted in docs/validation/contact-and-many-particle-scenes.md
Run: python -m fbmbench contact --sizes 1000 10000 100000 --steps 20

Scene: N spheres (R = 5 mm, 2500 kg/m^3) on a square lattice of spacing 2.002 R resting on the
floor of a box whose side holds ``ceil(sqrt(N / 10))`` of them (a column about 10 spheres high),
gravity 9.81 m/s^2, time step 1 ms, restitution 0.3, friction 0.5, 20 PGS sweeps per step (the
same in pybullet: ``numSolverIterations = 20``). Every step has about 3 N contacts. Each size
first takes 5 untimed steps (JIT compile and warm start), then ``--steps`` timed ones; the
figure is the mean wall time of a step, split into detection (broadphase + narrowphase) and
solve (PGS and position projection). pybullet (Bullet's sequential-impulse solver, C++) runs in
the same process right after, on one core (DIRECT mode, default settings, walls as planes), for
sizes up to ``--pybullet-max`` (its step grows faster than linearly here). Writes
``benchmarks/results/contact.md`` and ``.json``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from fbmflow.contact import ContactSet, Planes
from fbmflow.particles import Ball, Particles

RESULTS = Path(__file__).resolve().parents[1] / "results"
R, RHO, DT, G = 0.005, 2500.0, 1e-3, 9.81


def lattice(n: int):
    side = int(np.ceil(np.sqrt(n / 10.0)))
    k = np.arange(n)
    s = 2.002 * R
    X = np.column_stack([(k % side + 0.5) * s, ((k // side) % side + 0.5) * s,
                         (k // side**2) * s + 1.001 * R])
    return X, side * s


def run_fbmflow(n: int, steps: int):
    X, L = lattice(n)
    p = Particles.at_rest([Ball(R, 3)] * n, RHO, X)
    cs = ContactSet(Planes.box([0, 0, 0], [L, L, 10.0]), restitution=0.3, friction=0.5, iterations=20)
    acc, ang = np.tile([0.0, 0.0, -G], (n, 1)), np.zeros((n, 3))
    for _ in range(5):
        p, _ = cs.substep(p, acc, ang, DT)
    detect = solve = 0.0
    contacts = []
    start = time.perf_counter()
    for _ in range(steps):
        p, r = cs.substep(p, acc, ang, DT)
        detect += r.detect_s
        solve += r.solve_s
        contacts.append(r.contacts)
    total = (time.perf_counter() - start) / steps
    return {"n": n, "step_s": total, "detect_s": detect / steps, "solve_s": solve / steps,
            "contacts": float(np.mean(contacts)), "max_overlap_over_R": r.max_overlap / R,
            "max_speed": float(np.linalg.norm(p.velocity, axis=1).max())}


def run_pybullet(n: int, steps: int):
    import pybullet as pb

    X, L = lattice(n)
    client = pb.connect(pb.DIRECT)
    pb.setGravity(0, 0, -G, physicsClientId=client)
    pb.setPhysicsEngineParameter(fixedTimeStep=DT, numSolverIterations=20, numSubSteps=0,
                                 physicsClientId=client)
    plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
    pb.createMultiBody(0, plane, physicsClientId=client)
    for normal, offset in (([1, 0, 0], 0.0), ([-1, 0, 0], -L), ([0, 1, 0], 0.0), ([0, -1, 0], -L)):
        wall = pb.createCollisionShape(pb.GEOM_PLANE, planeNormal=normal, physicsClientId=client)
        pb.createMultiBody(0, wall, basePosition=[0, 0, 0], physicsClientId=client)
        pb.resetBasePositionAndOrientation(pb.getNumBodies(physicsClientId=client) - 1,
                                           np.array(normal) * offset, [0, 0, 0, 1], physicsClientId=client)
    sphere = pb.createCollisionShape(pb.GEOM_SPHERE, radius=R, physicsClientId=client)
    mass = RHO * 4.0 / 3.0 * np.pi * R**3
    start = time.perf_counter()
    for x in X:
        b = pb.createMultiBody(mass, sphere, basePosition=x.tolist(), physicsClientId=client)
        pb.changeDynamics(b, -1, restitution=0.3, lateralFriction=0.5, physicsClientId=client)
    build = time.perf_counter() - start
    for _ in range(5):
        pb.stepSimulation(physicsClientId=client)
    start = time.perf_counter()
    for _ in range(steps):
        pb.stepSimulation(physicsClientId=client)
    total = (time.perf_counter() - start) / steps
    pb.disconnect(client)
    return {"n": n, "step_s": total, "build_s": build}


def run(*, sizes: list[int] = (1000, 10000, 100000), steps: int = 20, pybullet: bool = True,
        pybullet_max: int = 10000) -> None:
    """Time the pile at each size (and pybullet on it) and write the table.

    Parameters
    ----------
    sizes : numbers of spheres
    steps : timed steps per size (after 5 untimed ones)
    pybullet : run pybullet on the same scene when it is installed (--no-pybullet: not)
    pybullet_max : the largest size pybullet runs
    """
    have_bullet = False
    if pybullet:
        try:
            import pybullet as pybullet_module  # noqa: F401
            have_bullet = True
        except ImportError:
            pass
    rows = []
    for n in sizes:
        row = run_fbmflow(n, steps)
        if have_bullet and n <= pybullet_max:
            row["pybullet_step_s"] = run_pybullet(n, steps)["step_s"]
        rows.append(row)
        print(json.dumps(row), flush=True)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "contact.json").write_text(json.dumps(rows, indent=1))
    lines = ["# Contact without fluid: settled pile of spheres", "",
             f"Command: `python -m fbmbench contact --sizes {' '.join(map(str, sizes))} "
             f"--steps {steps}`; mean of {steps} steps after 5 untimed ones, 2-core machine, "
             "one thread for the contact code.", "",
             "| N | contacts | fbmflow step [ms] | detect [ms] | solve [ms] | µs per sphere | "
             "max overlap / R | pybullet step [ms] |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        pyb = f"{1e3 * r['pybullet_step_s']:.1f}" if "pybullet_step_s" in r else \
            ("not run (N > --pybullet-max)" if have_bullet else "not installed")
        lines.append(f"| {r['n']} | {r['contacts']:.0f} | {1e3 * r['step_s']:.1f} | "
                     f"{1e3 * r['detect_s']:.1f} | "
                     f"{1e3 * r['solve_s']:.1f} | {1e6 * r['step_s'] / r['n']:.1f} | "
                     f"{r['max_overlap_over_R']:.1e} | {pyb} |")
    if len(rows) > 1:
        a, b = rows[0], rows[-1]
        slope = np.log(b["step_s"] / a["step_s"]) / np.log(b["n"] / a["n"])
        lines += ["", f"Growth of the fbmflow step time: N^{slope:.2f} from N = {a['n']} to {b['n']}."]
        bullet = [r for r in rows if "pybullet_step_s" in r]
        if len(bullet) > 1:
            a, b = bullet[0], bullet[-1]
            s2 = np.log(b["pybullet_step_s"] / a["pybullet_step_s"]) / np.log(b["n"] / a["n"])
            lines[-1] += f" pybullet: N^{s2:.2f} from N = {a['n']} to {b['n']}."
    (RESULTS / "contact.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

