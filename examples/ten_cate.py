# %% [markdown]
# # ten Cate et al. (2002): a sphere settling in a box
#
# Case E4 (silicone oil rho_f = 960 kg/m^3, mu = 0.058 Pa s), quarter box with two mirror planes.
# The 3D direct solve is expensive on a laptop: the full run (level 1, 6 cells per diameter) takes
# hours here; `FBMFLOW_EXAMPLE_SIZE=small` runs two steps at level 0.

# %%
import os

import matplotlib.pyplot as plt

import fbmflow as fb
from fbmflow.scenes.data import tencate2002

small = os.environ.get("FBMFLOW_EXAMPLE_SIZE") == "small"
case = "E4"
scene = fb.get_scene("ten-cate")
params = fb.from_dict(scene.Params, {"fluid": {"case": case},
                                     "time": {"t_end": 0.02 if small else 0.0}})
q = scene.run(params, 0 if small else 1).quantities
print(f"u_max = {q['max_settling_velocity']:.4f} m/s (experiment {tencate2002.U_MAX[case]} m/s)")

# %%
fig, ax = plt.subplots(1, 2, figsize=(10, 4))
ax[0].plot(q["t"], q["gap_over_d"], label="fbmflow")
ax[0].plot(*tencate2002.GAP[case].T, "o", mfc="none", label="PIV")
ax[0].set_ylabel("gap / d")
ax[1].plot(q["t"], q["settling_velocity"], label="fbmflow")
ax[1].plot(*tencate2002.VELOCITY[case].T, "o", mfc="none", label="PIV")
ax[1].set_ylabel("settling velocity [m/s]")
for a in ax:
    a.set_xlabel("t [s]")
    a.legend()
fig.savefig("ten_cate.png", dpi=100)
