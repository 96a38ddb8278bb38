"""Settling velocities of spheres in a periodic cube by Stokesian dynamics: an independent Stokes
reference for the hindered-settling ensembles, with the near field that the Ewald–RPY model
(:mod:`fbmbench.ewald_rpy`) lacks.

The solver is Townsend's Python implementation of Stokesian dynamics (Durlofsky, Brady & Bossis
1987; periodic by Ewald sums as Brady et al. 1988; github.com/Pecnut/stokesian-dynamics, MIT
licence, commit :data:`COMMIT`): the far field to the stresslet level (``M^inf``, FTS) and exact
two-sphere lubrication (``R^2B,exact``) between close pairs. It is not part of fbmflow and is not
installed with it: clone it and give its path. :func:`prepare` copies the checkout and adds one
position setup and one input setup (number :data:`SETUP`) that read the spheres and the box from a
file and push every sphere with a unit force along ``-z``; the solver itself is not changed.

Known accuracy: Stokesian dynamics truncates the far field at the stresslet, and for a simple cubic
array at ``phi = 0.2`` it settles 15 % faster than the exact solution (Sierou & Brady 2001, Fig. 9;
measured here: ``benchmarks/results/hindered_settling_sd.md``).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

COMMIT = "6b9117d1601c5e50dfea0475fd4f10d53447174a"
SETUP = 99
DT = 1.0  # the one Euler step's length (a radius moves U / U_0 / (6 pi) in it)

_POSITIONS = '''    if n == 99:  # fbmbench: spheres of radius 1 at the centres in the file SD_CONFIG
        import os
        with np.load(os.environ["SD_CONFIG"]) as c:
            sphere_positions = c["positions"]
        num_spheres = len(sphere_positions)
        sphere_sizes = np.array([1 for _ in range(num_spheres)])
        sphere_rotations = add_sphere_rotations_to_positions(
            sphere_positions, sphere_sizes, np.array([[1, 0, 0], [0, 0, 1]]))
        dumbbell_sizes = np.array([])
        dumbbell_positions = np.empty([0, 3])
        dumbbell_deltax = np.empty([0, 3])
        desc = "fbmbench"
    elif n == 1:
'''

_INPUTS = '''    elif n == 99:  # fbmbench: a unit force along -z on every sphere, the box in SD_CONFIG
        import os
        with np.load(os.environ["SD_CONFIG"]) as c:
            box_bottom_left = np.array(c["lower"], dtype=float)
            box_top_right = np.array(c["upper"], dtype=float)
        Fa_in[:] = [[0, 0, -1] for _ in range(num_spheres)]
        Ot_infinity = np.zeros(3)
        Et_infinity = np.zeros((3, 3))
        U_infinity = np.zeros(3)
        O_infinity = np.zeros(3)
        centre_of_background_flow = np.zeros(3)
        desc = "fbmbench"
    elif n == 1:
'''


def _insert(path: Path, anchor: str, text: str) -> None:
    """Put ``text`` in place of the first ``anchor`` of the file ``path``, unless it is there."""
    source = path.read_text()
    if "fbmbench" in source:
        return
    if anchor not in source:
        raise RuntimeError(f"{path}: '{anchor.strip()}' not found; is the checkout at commit {COMMIT}?")
    path.write_text(source.replace(anchor, text, 1))


def prepare(source: str | os.PathLike, work: str | os.PathLike) -> Path:
    """Copy the Stokesian-dynamics checkout ``source`` to ``work`` (once) and add setup
    :data:`SETUP`; Numba on, graphics off. Returns the folder to run ``run_simulation.py`` in.
    One process at a time per copy: the runs share its ``output`` folder."""
    source, work = Path(source).resolve(), Path(work).resolve()
    if not (source / "stokesian_dynamics" / "run_simulation.py").is_file():
        raise FileNotFoundError(f"{source} is not a checkout of github.com/Pecnut/stokesian-dynamics "
                                f"(git clone it and check out {COMMIT[:7]})")
    if not work.is_dir():
        shutil.copytree(source, work, ignore=shutil.ignore_patterns(".git"))
    root = work / "stokesian_dynamics"
    _insert(root / "setups" / "positions.py", "    if n == 1:\n", _POSITIONS)
    _insert(root / "setups" / "inputs.py", "    elif n == 1:\n", _INPUTS)
    settings = root / "settings.py"
    text = settings.read_text().replace("config.DISABLE_JIT = True", "config.DISABLE_JIT = False")
    settings.write_text(text.replace("view_graphics = True", "view_graphics = False"))
    return root


def settling_velocities(root: Path, X: np.ndarray, box: float, a: float) -> np.ndarray:
    """Settling velocity of each sphere (radius ``a``, centres ``X (n, 3)`` in the periodic cube of
    side ``box``, each pushed by the same force along ``-z``) over one sphere's Stokes velocity
    ``F / (6 pi mu a)``; (n,) float64, positive downwards. One Euler step of :data:`DT` with force
    1, viscosity 1 and radius 1 (so ``U_0 = 1 / (6 pi)``); the solver wraps the centres back into
    the box after the step, which is undone here."""
    X = np.mod(np.asarray(X, dtype=float), box) / a  # radius 1
    side = box / a
    out = root / "output"
    out.mkdir(exist_ok=True)
    config = out / "fbmbench-config.npz"
    for old in out.glob(f"*-s{SETUP}-i{SETUP}-*.npz"):
        old.unlink()
    np.savez(config, positions=X - side / 2, lower=[-side / 2] * 3, upper=[side / 2] * 3)
    done = subprocess.run([sys.executable, "run_simulation.py", str(SETUP), str(SETUP), str(DT), "1", "fte"],
                          cwd=root, env=dict(os.environ, SD_CONFIG=str(config)), capture_output=True,
                          text=True)
    found = [f for f in out.glob(f"*-s{SETUP}-i{SETUP}-*.npz") if "temp" not in f.name.lower()]
    if done.returncode or len(found) != 1:
        raise RuntimeError(f"Stokesian dynamics failed:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    with np.load(found[0]) as data:
        centres = data["centres"]
    dz = centres[1, :, 2] - centres[0, :, 2]
    dz = np.mod(dz + side / 2, side) - side / 2  # across the periodic faces
    return -dz / DT * 6.0 * math.pi
