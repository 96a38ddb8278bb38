"""Hindered settling of random suspensions from an ensemble of frozen configurations (issue 29,
item 3), extrapolated in the particle count against Richardson & Zaki.

Run:  python benchmarks/bench_hindered_settling.py [--counts 8 20] [--seeds 0 1 2] [--level 2]
      [--fraction 0.2] [--dt 0.1] [--steps 3] [--min-gap 0.02] [--moving] [--set KEY=VALUE ...]

At small Reynolds numbers the mean settling velocity of a suspension is an average over its
configurations (Ladd 1990), each settling at the velocity its particles' mobilities give. So
instead of one long run, ``suspension-3d`` is run from ``--seeds`` independent random placements
(gaps of at least ``--min-gap`` diameters, repulsion off: the configurations of hard spheres
placed at random, with no pair force) held in place (``particles.frozen``) for ``--steps`` steps
of ``--dt`` = 0.1 s from rest, and the settling velocity is the mean over the steps after the
first. A backward-Euler step of ``dt`` screens the flow beyond ``sqrt(nu dt)`` (1.4 d here): the
box's longest wave, of length ``L``, reaches ``(2 pi / L)^2 nu dt / (1 + (2 pi / L)^2 nu dt)`` of its
steady amplitude per step (0.91 for 8 spheres at 0.2, 0.78 for 40), so one step from rest reads
the configuration's settling 4-5 % low; steps 2 and 3 agree to 0.5 %. ``--moving`` lets the
particles move (the one-step protocol of the first ensembles, ``--steps 1``).

A periodic box of ``N`` particles misses the fluctuations longer than the box, which hinder the
settling by about ``1.76 S(0) (phi / N)^(1/3) U_0`` (the Hasimoto coefficient times the
structure factor at zero wave number, ``S(0) = (1 - phi)^4 / (1 + 2 phi)^2`` for hard spheres;
Ladd 1997). The ratio to Richardson–Zaki (``richardson_zaki`` of the scene: Schiller–Naumann
terminal velocity, Garside & Al-Dibouni's exponent) is therefore fitted as
``r(N) = r_inf - c N^(-1/3)`` over the counts run, and ``r_inf`` is the infinite suspension's.

Results: ``benchmarks/results/hindered_settling.md``, ``.json`` and ``.png``.
"""
from __future__ import annotations

import argparse

import numpy as np
from fbmbench.common import (
    RESULTS,
    RunFailed,
    merge_row,
    parse_settings,
    provenance,
    run_scene,
    warm_up,
    write_text,
)

NAME = "hindered_settling"
HASIMOTO = 1.7601


def structure_factor(phi: float) -> float:
    """Percus–Yevick structure factor of hard spheres at zero wave number."""
    return (1.0 - phi) ** 4 / (1.0 + 2.0 * phi) ** 2


def ladd(row: dict, n: int) -> float:
    """Ladd's finite-size hindrance of ``n`` particles at the row's fraction, over its
    Richardson–Zaki velocity (``U_0`` = the terminal velocity)."""
    phi = row["volume_fraction"]
    return HASIMOTO * structure_factor(phi) * (phi / n) ** (1 / 3) * row["terminal_velocity"] \
        / row["richardson_zaki"]


def run(count: int, seed: int, level: int, fraction: float, dt: float, steps: int, min_gap: float,
        extra: dict) -> dict:
    settings = {"particles.count": count, "particles.seed": seed, "particles.volume_fraction": fraction,
                "particles.min_gap": min_gap, "repulsion.enabled": False, "time.dt": dt,
                "time.t_end": round(dt * steps, 12), "particles.frozen": True, **extra}
    row = {"count": count, "seed": seed, "level": level, "fraction": fraction, "min_gap": min_gap,
           "steps": steps, "settings": settings, **provenance()}
    try:
        s = run_scene("suspension-3d", level, settings)
    except RunFailed as error:
        return {**row, "failure": str(error)}
    q = s["quantities"]
    series = np.array(q["settling_velocity"][min(2, steps):])  # past the first step (one step: itself)
    return {**row, "failure": "", "volume_fraction": q["volume_fraction"],
            "cells_per_diameter": q["cells_per_diameter"], "n_dofs": s["n_dofs"], "wall_s": s["wall_s"],
            "settling": float(series.mean()), "series": q["settling_velocity"],
            "richardson_zaki": q["richardson_zaki"], "terminal_velocity": q["terminal_velocity"],
            "ratio": float(series.mean()) / q["richardson_zaki"], "max_overlap": q["max_overlap"],
            "array": q["array_velocity"]}


def groups(rows: list[dict]) -> dict:
    """Configuration ratios of the rows that ran, by (level, fraction, min_gap, repulsion on, dt, steps,
    protocol), then count: one ratio per seed (rows of one seed with other solver settings are
    averaged)."""
    seeds: dict = {}
    for r in rows:
        if not r["failure"]:
            key = (r["level"], r["fraction"], r["min_gap"], repulsion(r), r["settings"]["time.dt"],
                   r["steps"], protocol(r))
            seeds.setdefault(key, {}).setdefault(r["count"], {}).setdefault(r["seed"], []).append(r)
    return {key: {n: [(float(np.mean([r["ratio"] for r in rs])), rs[0]) for rs in by_seed.values()]
                  for n, by_seed in by_count.items()} for key, by_count in seeds.items()}


def repulsion(row: dict) -> str:
    return "on" if row["settings"]["repulsion.enabled"] else "off"


def protocol(row: dict) -> str:
    return "frozen" if row["settings"].get("particles.frozen") else "moving"


def extrapolate(by_count: dict) -> tuple[float, float] | None:
    """``(r_inf, c)`` of the least-squares fit ``r = r_inf - c N^(-1/3)`` to the ensemble means
    (each weighted by its number of configurations); None with fewer than two counts."""
    if len(by_count) < 2:
        return None
    x = np.array([n ** (-1 / 3) for n in by_count])
    y = np.array([np.mean([ratio for ratio, _ in rs]) for rs in by_count.values()])
    w = np.sqrt([len(rs) for rs in by_count.values()])
    A = np.column_stack([np.ones_like(x), -x]) * w[:, None]
    r_inf, c = np.linalg.lstsq(A, y * w, rcond=None)[0]
    return float(r_inf), float(c)


def corrected(by_count: dict) -> tuple[float, float, float]:
    """Ladd's law with its own slope, fitted to every configuration: ``(r_inf, its standard error,
    chi^2 per degree of freedom of the ensemble means about the law)``. ``r_inf`` is the mean of
    the configurations' ``ratio + ladd``; chi^2 compares each count's mean of it with ``r_inf``
    in units of its standard error (the configurations' scatter pooled over the counts), so a
    value well above 1 says the counts do not follow the law."""
    values = {n: np.array([ratio + ladd(row, n) for ratio, row in rs]) for n, rs in by_count.items()}
    every = np.concatenate(list(values.values()))
    r_inf = float(every.mean())
    spread = np.concatenate([v - v.mean() for v in values.values()])
    dof = len(every) - len(values)
    sd = float(np.sqrt(spread @ spread / dof)) if dof > 0 else float("nan")
    chi2 = sum(len(v) * (v.mean() - r_inf) ** 2 for v in values.values()) / sd ** 2
    return r_inf, sd / np.sqrt(len(every)), float(chi2 / max(len(values) - 1, 1))


def write(rows: list[dict]) -> None:
    lines = ["# Hindered settling from frozen random configurations (hindered_settling)", "",
             "`suspension-3d` (d = 0.1 cm, rho_s = 1.5, viscosity 0.2 g/(cm s), Re_t 0.6), spheres placed "
             "at random with repulsion off, held in place ('frozen': the mean over steps 2, 3, ... of dt "
             "from rest) or moving (the earlier protocols: one step of dt from rest, or the mean over steps "
             "2, 3, ... of 0.01 s). Settling velocity relative to the mixture, and "
             "its ratio to Richardson-Zaki V_t (1 - phi)^n (V_t: Schiller-Naumann, n: Garside & "
             "Al-Dibouni at Re_t) at the box's own fraction. Wall time without the JIT warm-up, 2-core "
             "machine. Reproduce: `python benchmarks/bench_hindered_settling.py --counts N --seeds S "
             "--fraction PHI [--set coupling.scheme=implicit] [--set solver.linear=multigrid]`.", "",
             "| spheres | seed | level | cells/d | phi (box) | min gap / d | repulsion | unknowns | "
             "steps x dt | particles | coupling | wall s | settling cm/s | Richardson-Zaki cm/s | ratio | "
             "array cm/s | "
             "max overlap / r | failure | measured |", "|---" * 19 + "|"]
    for r in sorted(rows, key=lambda r: (r["level"], r["fraction"], r["min_gap"], r["count"], r["seed"])):
        st = r["settings"]
        head = (f"| {r['count']} | {r['seed']} | {r['level']} | {r.get('cells_per_diameter', 0):.0f} | "
                f"{r.get('volume_fraction', r['fraction']):.4f} | {r['min_gap']} | {repulsion(r)} | "
                f"{r.get('n_dofs', '')} | {r['steps']} x {st['time.dt']} | {protocol(r)} | "
                f"{st['coupling.scheme']} |")
        if r["failure"]:
            lines.append(f"{head} | | | | | | | {r['failure']} | {r['date']} {r['commit']} |")
            continue
        lines.append(f"{head} {r['wall_s']:.0f} | {r['settling']:.4g} | {r['richardson_zaki']:.4g} | "
                     f"{r['ratio']:.3f} | {r['array']:.4g} | {r['max_overlap']:.2g} | – | "
                     f"{r['date']} {r['commit']} |")
    lines += ["", "Ensemble means (ratio to Richardson-Zaki; +- the standard error over the seeds) and the "
              "fit r(N) = r_inf - c N^(-1/3). 'Ladd' is the finite-size hindrance "
              f"{HASIMOTO} S(0) (phi/N)^(1/3) U_0 / V_RZ expected from the box (S(0) of hard spheres, "
              "U_0 = V_t).", "",
              "| level | phi | min gap / d | repulsion | steps x dt s | particles | spheres | "
              "configurations | ratio | "
              "Ladd's finite-size term | ratio + Ladd | fit r_inf | fit c | Ladd's law r_inf | "
              "chi^2 / dof |", "|---" * 15 + "|"]
    for (level, fraction, gap, rep, dt, steps, how), by_count in sorted(groups(rows).items()):
        fit = extrapolate(by_count)
        law = corrected(by_count)
        for n, rs in sorted(by_count.items()):
            ratios = np.array([ratio for ratio, _ in rs])
            err = f" +- {ratios.std(ddof=1) / np.sqrt(len(ratios)):.3f}" if len(ratios) > 1 else ""
            term = np.mean([ladd(row, n) for _, row in rs])
            fits = f"{fit[0]:.3f} | {fit[1]:.3f}" if fit else " | "
            laws = f"{law[0]:.3f} +- {law[1]:.3f} | {law[2]:.2f}" if fit and np.isfinite(law[1]) else " | "
            lines.append(f"| {level} | {fraction} | {gap} | {rep} | {steps} x {dt} | {how} | {n} | "
                         f"{len(rs)} | "
                         f"{ratios.mean():.3f}{err} | {term:.3f} | {ratios.mean() + term:.3f} | {fits} | "
                         f"{laws} |")
    write_text(RESULTS / f"{NAME}.md", "\n".join(lines) + "\n")
    plot(rows)


def plot(rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    chosen = {key: by_count for key, by_count in groups(rows).items() if key[-1] == "frozen"}
    for k, ((level, fraction, gap, rep, dt, steps, how), by_count) in enumerate(sorted(chosen.items())):
        label = f"phi {fraction}, {2 ** level} cells/d, {steps} x {dt} s"
        for n, rs in by_count.items():
            ax.plot([n ** (-1 / 3)] * len(rs), [ratio for ratio, _ in rs], "o", ms=3, alpha=0.5,
                    color=f"C{k}")
        fit = extrapolate(by_count)
        if fit:
            x = np.linspace(0.0, max(n ** (-1 / 3) for n in by_count), 20)
            n0 = min(by_count)
            slope = ladd(by_count[n0][0][1], n0) / n0 ** (-1 / 3)
            law = corrected(by_count)
            ax.plot(x, law[0] - slope * x, ":", color=f"C{k}",
                    label=f"{label}: Ladd's law, r_inf = {law[0]:.2f}")
            ax.plot(x, fit[0] - fit[1] * x, "-", color=f"C{k}", label=f"{label}: fit, r_inf = {fit[0]:.2f}")
    ax.axhline(1.0, color="k", lw=0.8, label="Richardson-Zaki")
    ax.axhspan(0.9, 1.1, color="k", alpha=0.08, label="10 %")
    ax.set_xlabel("N^(-1/3)")
    ax.set_ylabel("settling velocity / Richardson-Zaki")
    ax.set_xlim(left=0.0)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(RESULTS / f"{NAME}.png", dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[8, 24])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--level", type=int, default=2, help="2^L cells per diameter")
    ap.add_argument("--fraction", type=float, default=0.2)
    ap.add_argument("--dt", type=float, default=0.1, help="time step [s]")
    ap.add_argument("--moving", action="store_true", help="let the particles move during the steps")
    ap.add_argument("--steps", type=int, default=3,
                    help="steps per configuration: at least 3 (the first is the flow's start-up), or one "
                         "long step (backward Euler then gives the configuration's steady settling)")
    ap.add_argument("--min-gap", type=float, default=0.02, help="smallest gap at the start, in diameters")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="more scene settings")
    args = ap.parse_args(argv)
    if args.steps == 2:
        ap.error("--steps must be 1 or at least 3 (the first step is the flow's start-up)")
    extra = {"coupling.scheme": "newton-krylov", **({"particles.frozen": False} if args.moving else {}),
             **parse_settings(args.set)}
    warm_up("suspension-3d", **{"particles.count": 1, "time.t_end": 0.02, "time.dt": 0.01})
    for count in args.counts:
        for seed in args.seeds:
            row = run(count, seed, args.level, args.fraction, args.dt, args.steps, args.min_gap, extra)
            print({k: v for k, v in row.items() if k not in ("settings", "series")}, flush=True)
            write(merge_row(NAME, row, lambda a, b: (a["count"], a["seed"], a["level"], a["settings"]) ==
                            (b["count"], b["seed"], b["level"], b["settings"])))


if __name__ == "__main__":
    main()
