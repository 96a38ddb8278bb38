# %% [markdown]
# # Drafting, kissing and tumbling
#
# Two disks settle one above the other (Uhlmann's set-up, rho_s / rho_f = 1.5). The trailing disk
# falls in the wake of the leading one (drafting), catches up (kissing) and overtakes it
# (tumbling). Hard contact keeps them apart; the coupling is implicit.
# `FBMFLOW_EXAMPLE_SIZE=small` runs 0.02 s at level 0.

# %%
import os

import matplotlib.pyplot as plt

import fbmflow as fb

small = os.environ.get("FBMFLOW_EXAMPLE_SIZE") == "small"
scene = fb.get_scene("dkt-2d")
params = fb.from_dict(scene.Params, {"case": {"setup": "uhlmann"},
                                     "time": {"t_end": 0.02 if small else 0.4}})
q = scene.run(params, 0 if small else 2).quantities
print("kiss at", q["t_kiss"], "s; tumble at", q["t_tumble"], "s (Koblitz et al. 2017: 0.175, 0.26)")

# %%
fig, ax = plt.subplots(1, 2, figsize=(10, 4))
for who, style in (("leading", "-"), ("trailing", "--")):
    ax[0].plot(q["t"], q[f"y_{who}"], style, label=who)
    ax[1].plot(q[f"x_{who}"], q[f"y_{who}"], style, label=who)
ax[0].set_xlabel("t [s]")
ax[0].set_ylabel("y [cm]")
ax[1].set_xlabel("x [cm]")
ax[1].set_ylabel("y [cm]")
ax[1].set_aspect("equal")
for a in ax:
    a.legend()
fig.savefig("dkt.png", dpi=100)
