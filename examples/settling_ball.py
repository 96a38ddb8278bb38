# %% [markdown]
# # A ball settles: the Python API
#
# A disk (d = 0.25 cm, rho_s = 1.25 g/cm^3) settles in a closed 2 x 6 cm box of fluid
# (rho_f = 1, mu = 0.1 g/(cm s)), built from the typed parameter sections of `fbmflow` instead of
# a built-in scene. We run it on two meshes, read the positions, velocities and forces from the
# step reports and the flow from the simulation, and compare the settling velocity with Koblitz et
# al.'s (2017) body-fitted result. `FBMFLOW_EXAMPLE_SIZE=small` makes it a few-second smoke run.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np

import fbmflow as fb
from fbmflow.scenes.data import koblitz2017

small = os.environ.get("FBMFLOW_EXAMPLE_SIZE") == "small"
cells_per_cm = [8] if small else [8, 16]
t_end = 0.05 if small else 0.6

# %%
fluid = fb.FluidParams(density=1.0, viscosity=0.1, gravity=980.0)
time = fb.TimeParams(dt=0.01 if small else 0.005, t_end=t_end, scheme="crank-nicolson")
runs = {}
for n in cells_per_cm:
    mesh = fb.StructuredMesh.box((2 * n, 6 * n), upper=(2.0, 6.0))
    disk = fb.Particles.at_rest([fb.Ball(0.125, dim=2)], density=1.25, position=[[1.0, 4.0]])
    sim = fb.Simulation(mesh, disk, fluid, time=time, coupling=fb.CouplingParams(integrator="trapezoidal"),
                        repulsion=fb.RepulsionParams())
    runs[n] = sim.run()
    last = runs[n][-1]
    print(f"{n / 4:g} cells per diameter: settling at {-last.velocity[0, 1]:.3f} cm/s, drag "
          f"{last.force[0, 1]:.3f} dyn/cm, {sum(r.newton_iterations for r in runs[n])} Newton iterations")

# %% [markdown]
# The flow around the disk at the end, sampled on a line through its centre:

# %%
x = np.linspace(0.0, 2.0, 101)
line = np.column_stack([x, np.full_like(x, sim.particles.position[0, 1])])
v_line = sim.velocity_at(line)[:, 1]

# %%
fig, ax = plt.subplots(1, 2, figsize=(10, 4))
for n, reports in runs.items():
    ax[0].plot([r.t for r in reports], [-r.velocity[0, 1] for r in reports], label=f"{n / 4:g} cells/d")
ax[0].plot(*koblitz2017.VELOCITY.T, "k.", ms=3, label="Koblitz et al. 2017")
ax[0].set_xlim(0, t_end)
ax[0].set_xlabel("t [s]")
ax[0].set_ylabel("settling velocity [cm/s]")
ax[0].legend()
ax[1].plot(x, v_line)
ax[1].set_xlabel("x [cm]")
ax[1].set_ylabel("vertical fluid velocity [cm/s]")
for a in ax:
    a.grid(alpha=0.3)
fig.savefig("settling_ball.png", dpi=100)
