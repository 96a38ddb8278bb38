# %% [markdown]
# # A fluidised bed
#
# Disks rest at the bottom of a channel; fluid enters through the bottom. Above the minimum
# fluidisation velocity the bed expands. We compare the bed height for two inflow velocities.
# `FBMFLOW_EXAMPLE_SIZE=small` runs 20 disks for 0.02 s.

# %%
import os

import matplotlib.pyplot as plt

import fbmflow as fb

small = os.environ.get("FBMFLOW_EXAMPLE_SIZE") == "small"
scene = fb.get_scene("fluidized-bed-2d")
runs = {}
for inflow in ([5.0] if small else [1.0, 3.0]):
    data = {"inflow": {"velocity": inflow}, "time": {"t_end": 0.02 if small else 1.0}}
    if small:
        data["particles"] = {"count": 20}
    runs[inflow] = scene.run(fb.from_dict(scene.Params, data), 1).quantities
    print(f"inflow {inflow} cm/s: bed height {runs[inflow]['bed_height'][0]:.2f} -> "
          f"{runs[inflow]['bed_height'][-1]:.2f} cm, max overlap {runs[inflow]['max_overlap']:.1e}")

# %%
fig, ax = plt.subplots(figsize=(6, 4))
for inflow, q in runs.items():
    ax.plot(q["t"], q["bed_height"], label=f"inflow {inflow} cm/s")
ax.set_xlabel("t [s]")
ax.set_ylabel("bed height [cm]")
ax.legend()
fig.savefig("fluidized_bed.png", dpi=100)
