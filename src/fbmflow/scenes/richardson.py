"""Error estimates of a run's quantities by Richardson extrapolation over mesh levels.

A quantity ``q_L`` computed at level ``L`` (cells of ``h = h_0 / 2^L``, and with a time step that
follows the mesh, ``dt`` halving too) behaves in the asymptotic range as ``q_L = q* + C h^p``.
From three levels the observed order is

.. math:: p = \\log_2 \\frac{q_{L-1} - q_{L-2}}{q_L - q_{L-1}},

and the error of the finest value and the extrapolated value are

.. math:: e_L = q^* - q_L \\approx \\frac{q_L - q_{L-1}}{2^p - 1}, \\qquad q^* \\approx q_L + e_L.

The levels are taken to be in the asymptotic range when the two differences have the same sign,
the finer one is the smaller, and ``p`` lies in :data:`ORDER_RANGE`; otherwise no number is
given, only the reason. From two levels the order cannot be observed: the estimate takes the
order given (``order``) and says that the range was not checked.
"""
from __future__ import annotations

import math
import textwrap

import numpy as np

#: observed orders taken as asymptotic behaviour (outside: the levels are not yet in the range,
#: or the quantity does not converge like a power of h)
ORDER_RANGE = (0.5, 4.0)
#: the quantities of a summary that are no results of the physics: never estimated
BOOKKEEPING = ("cells_per_diameter", "time_step", "courant_number", "time_step_smallest", "time_step_largest",
               "rejected_steps")


def richardson(values: list[float], order: float = 1.0) -> dict:
    """The error estimate of the last of ``values`` (the quantity at consecutive levels, coarsest
    first, two or three of them).

    Returns a dict: ``value`` (the finest), ``error`` (the estimate of ``q* - q_L``, None when the
    levels are not in the asymptotic range), ``extrapolated``, ``order`` (observed from three
    levels, ``order`` from two), ``asymptotic`` (True, False, or None: not checked, two levels)
    and ``reason`` (why no number, or the caveat).
    """
    q = [float(v) for v in values]
    if len(q) not in (2, 3):
        raise ValueError(f"richardson: give the quantity at 2 or 3 levels, got {len(q)}")
    fine, d2 = q[-1], q[-1] - q[-2]
    result = {"value": fine, "levels_values": q, "error": None, "extrapolated": None, "order": None,
              "asymptotic": None, "reason": ""}
    if len(q) == 2:
        error = d2 / (2.0**order - 1.0)
        result.update(error=error, extrapolated=fine + error, order=order,
                      reason=f"two levels: order {order:g} assumed, the asymptotic range not checked")
        return result
    d1 = q[1] - q[0]
    if d1 == 0.0 and d2 == 0.0:
        result.update(error=0.0, extrapolated=fine, asymptotic=True, reason="the same at all three levels")
        return result
    if d1 * d2 <= 0.0:
        result.update(asymptotic=False, reason="the differences between levels change sign")
        return result
    if abs(d2) >= abs(d1):
        result.update(asymptotic=False, reason="the finer difference is not smaller: not converging yet")
        return result
    p = math.log2(abs(d1) / abs(d2))
    if not ORDER_RANGE[0] <= p <= ORDER_RANGE[1]:
        result.update(order=p, asymptotic=False,
                      reason=f"observed order {p:.2f} outside {ORDER_RANGE[0]:g}-{ORDER_RANGE[1]:g}")
        return result
    error = d2 / (2.0**p - 1.0)
    result.update(error=error, extrapolated=fine + error, order=p, asymptotic=True)
    return result


def estimated_quantities(quantities: dict) -> list[str]:
    """The names of a summary's quantities that get an estimate: finite real scalars that are
    no error or deviation against a reference (``*_error``, ``*deviation*``: their limit is the
    model's distance to the reference, often a largest one over a curve, not a value that
    converges like ``C h^p``) and no bookkeeping (:data:`BOOKKEEPING`)."""
    return [k for k, v in quantities.items() if isinstance(v, float) and math.isfinite(v)
            and not k.endswith("_error") and "deviation" not in k and k not in BOOKKEEPING]


def estimate(summaries: list[dict], order: float = 1.0) -> dict:
    """Per quantity of the finest of ``summaries`` (consecutive levels, coarsest first), the
    :func:`richardson` estimate; quantities missing at a coarser level are left out."""
    names = estimated_quantities(summaries[-1]["quantities"])
    out = {}
    for name in names:
        values = [s["quantities"].get(name) for s in summaries]
        if all(isinstance(v, (int, float)) and v is not None and math.isfinite(v) for v in values):
            out[name] = richardson(values, order)
    return out


def plot(estimates: dict, levels: list[int], path, title: str) -> bool:
    """The quantities against the level, with the extrapolated value and the estimated error band
    of the finest (at most six quantities); False when there is nothing to draw."""
    from .base import pyplot, save_figure

    names = list(estimates)[:6]
    if not names:
        return False
    plt = pyplot()
    cols = min(3, len(names))
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.2 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names):
        e = estimates[name]
        ax.plot(levels, e["levels_values"], "o-", label="computed")
        if e["error"] is not None:
            ax.axhline(e["extrapolated"], ls="--", c="k", lw=1, label="extrapolated")
            ax.fill_between([levels[-1] - 0.15, levels[-1] + 0.15], e["value"] - abs(e["error"]),
                            e["value"] + abs(e["error"]), color="C1", alpha=0.4, label="error estimate")
            ax.set_title(f"{name}\nerror {e['error']:+.3g} (order {e['order']:.2f})", fontsize=9)
        else:
            ax.set_title(f"{name}\n" + textwrap.fill(f"no estimate: {e['reason']}", 45), fontsize=8)
        ax.set_xticks(levels)
        ax.set_xlabel("level")
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def table(estimates: dict) -> str:
    """One line per quantity: value, error estimate (relative), extrapolated value, order."""
    lines = []
    for name, e in estimates.items():
        if e["error"] is None:
            lines.append(f"{name} = {e['value']:.6g}: no estimate ({e['reason']})")
            continue
        rel = abs(e["error"]) / abs(e["value"]) if e["value"] else np.inf
        note = f"; {e['reason']}" if e["reason"] else ""
        lines.append(f"{name} = {e['value']:.6g} +- {abs(e['error']):.2g} ({100 * rel:.2g} %), extrapolated "
                     f"{e['extrapolated']:.6g}, order {e['order']:.2f}{note}")
    return "\n".join(lines)
