"""Figures of a study (matplotlib, Agg): output distributions, sensitivity ranking, operating map."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _scale(col: str) -> tuple[float, str]:
    if col.endswith("_m_s"):
        return 1e3, "mm/s"
    if col.endswith("_s"):
        return 1.0, "s"
    if col.endswith("_m"):
        return 1e3, "mm"
    return 1.0, ""


def output_name(col: str) -> str:
    """An output's name without its unit suffix (the axis gives the unit shown): mean_speed_m_s -> mean speed."""
    for suffix in ("_m_s", "_s", "_m"):
        if col.endswith(suffix):
            col = col[: -len(suffix)]
            break
    return col.replace("_", " ")


#: operating variable -> axis label
OPERATING_AXES = {"V0_V": "V0 [V]", "load_kg": "load [kg]", "frequency_Hz": "drive frequency [Hz]",
                  "temperature_degC": "temperature [°C]", "direction": "direction [-]"}


def _op_label(row) -> str:
    return (f"{row['V0_V']:g} V, {row['load_kg']:+g} kg, dir {int(row['direction']):+d}, "
            f"{row['frequency_Hz'] / 1e3:g} kHz, {row['temperature_degC']:g} degC")


def output_distributions(res, path) -> Path:
    """Every sample's outputs per operating point: their distribution (violin), p5-p95 bars and the p50."""
    plt = _plt()
    cols = [c for c in res.outputs if c != "stalled"]
    ops = list(res.table.groupby("op_id", sort=True))
    fig, axes = plt.subplots(len(cols), 1, figsize=(max(6.0, 1.2 * len(ops) + 3), 2.3 * len(cols) + 0.6),
                             squeeze=False, sharex=True)
    for ax, c in zip(axes[:, 0], cols):
        k, unit = _scale(c)
        for i, (_, g) in enumerate(ops):
            x = g.loc[g["status"] == "ok", c].astype(float).to_numpy() * k
            x = x[np.isfinite(x)]
            if not len(x):
                continue
            if np.ptp(x) > 0:
                parts = ax.violinplot([x], positions=[i], widths=0.6, showextrema=False)
                for body in parts["bodies"]:
                    body.set_alpha(0.35)
            ax.plot(np.full(len(x), i), x, "_", ms=8, alpha=0.3, color="C0",
                    label="samples (violin: their density)" if i == 0 else None)
            p5, p50, p95 = np.percentile(x, (5, 50, 95))
            ax.errorbar([i + 0.38], [p50], yerr=[[p50 - p5], [p95 - p50]], fmt="s", color="C3", ms=4, capsize=3,
                        label="p50, p5-p95" if i == 0 else None)
        ax.set_ylabel(f"{output_name(c)}\n[{unit}]" if unit else output_name(c), fontsize=9)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xticks(range(len(ops)), [_op_label(g.iloc[0]).replace(", ", "\n", 2) for _, g in ops],
                           fontsize=7)
    axes[0, 0].legend(fontsize=7)
    axes[0, 0].set_title(f"{res.spec.name}: {len(res.table)} samples", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def sensitivity_bars(res, path) -> Path | None:
    """SRC (and Sobol' S1/ST for a Saltelli design) of each parameter on the first output, first point."""
    plt = _plt()
    src = res.sensitivity
    if src is None or not len(src):
        return None
    c = res.outputs[0] if res.outputs[0] != "stalled" else src["output"].iloc[0]
    g = src[(src["op_id"] == src["op_id"].min()) & (src["output"] == c)].sort_values("rank")
    sob = res.sobol
    fig, ax = plt.subplots(figsize=(7, 0.45 * len(g) + 1.6))
    y = np.arange(len(g))
    ax.barh(y - 0.2, g["src"], height=0.4, label=f"SRC (R^2 = {g['r2'].iloc[0]:.2f})")
    ax.axvline(0, color="k", lw=0.8)
    if sob is not None and len(sob):
        s = sob[(sob["op_id"] == g["op_id"].iloc[0]) & (sob["output"] == c)].set_index("parameter")
        s = s.reindex(g["parameter"])
        ax.barh(y + 0.2, s["ST"], height=0.2, xerr=s["ST_conf"], label="Sobol' total ST")
        ax.barh(y, s["S1"], height=0.2, xerr=s["S1_conf"], label="Sobol' first order S1")
    ax.set_yticks(y, g["parameter"])
    ax.invert_yaxis()
    ax.set_xlabel(f"sensitivity of {output_name(c)} [-]")
    ax.legend(fontsize=7)
    op = res.table[res.table["op_id"] == g["op_id"].iloc[0]].iloc[0]
    ax.set_title(f"{res.spec.name}\nwhich parameter matters most at {_op_label(op)}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def operating_map(res, path) -> Path:
    """p50 of the first output with its p5-p95 band over the first varying operating variable."""
    plt = _plt()
    s = res.summary
    c = next(o for o in res.outputs if o != "stalled")
    k, unit = _scale(c)
    s = s[s["output"] == c]
    varying = [v for v in ("V0_V", "load_kg", "frequency_Hz", "temperature_degC", "direction") if s[v].nunique() > 1]
    xcol = varying[0]
    groups = varying[1:]
    fig, ax = plt.subplots(figsize=(7, 4))
    for key, g in (s.groupby(groups, sort=True) if groups else [((), s)]):
        g = g.sort_values(xcol)
        label = ", ".join(f"{n} {v:g}" for n, v in zip(groups, np.atleast_1d(key))) or c
        line, = ax.plot(g[xcol], g["p50"] * k, "o-", label=label)
        ax.fill_between(g[xcol], g["p5"] * k, g["p95"] * k, color=line.get_color(), alpha=0.2)
    ax.set_xlabel(OPERATING_AXES.get(xcol, xcol))
    ax.set_ylabel(f"{output_name(c)} [{unit}]: p50, band p5-p95")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
