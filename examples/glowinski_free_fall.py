# %% [markdown]
# # Glowinski's free fall of a disk
#
# A disk (d = 0.25 cm, rho_s = 1.25 g/cm^3) settles in a closed 2 x 6 cm channel of fluid
# (rho_f = 1, mu = 0.1 g/(cm s)). We run the built-in scene at two mesh levels and compare the
# settling velocity with Koblitz et al.'s (2017) body-fitted overset-grid result: accuracy against
# wall time.
#
# Run as a notebook or as a script (`python examples/glowinski_free_fall.py`);
# `FBMFLOW_EXAMPLE_SIZE=small` makes it a few-second smoke run.

# %%
import os
import time

import matplotlib.pyplot as plt

import fbmflow as fb
from fbmflow.scenes.data import koblitz2017

small = os.environ.get("FBMFLOW_EXAMPLE_SIZE") == "small"
levels = [0] if small else [1, 2]
t_end = 0.02 if small else 0.65

# %%
scene = fb.get_scene("glowinski-free-fall")
results = {}
for level in levels:
    params = fb.from_dict(scene.Params, {"time": {"t_end": t_end}})
    start = time.perf_counter()
    q = scene.run(params, level).quantities
    results[level] = q
    print(f"level {level}: v_max = {q['max_settling_velocity']:.3f} cm/s "
          f"({100 * (q['max_settling_velocity'] / koblitz2017.V_MAX - 1):+.1f} % against Koblitz et al.), "
          f"Re_max = {q['max_reynolds_number']:.2f}, {time.perf_counter() - start:.1f} s")

# %%
fig, ax = plt.subplots(figsize=(6, 4))
for level, q in results.items():
    ax.plot(q["t"], [-v for v in q["v"]], label=f"level {level} ({2**level} cells/d)")
ax.plot(*koblitz2017.VELOCITY.T, "k.", ms=3, label="Koblitz et al. 2017")
ax.set_xlim(0, t_end)
ax.set_xlabel("t [s]")
ax.set_ylabel("settling velocity [cm/s]")
ax.legend()
ax.grid(alpha=0.3)
fig.savefig("glowinski_free_fall.png", dpi=100)
