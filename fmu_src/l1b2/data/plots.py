"""PNG figures for every report (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from . import measurements as dataio
from .metrics import evaluation_mask


def pyplot():
    """matplotlib.pyplot with the non-interactive Agg backend (unless a backend was chosen already)."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    return plt


#: most points a scatter panel draws (a display limit: the data and every figure computed from them stay whole)
DISPLAY_POINTS = 20000


def display_rows(n: int, limit: int = DISPLAY_POINTS) -> np.ndarray:
    """Indices of at most ``limit`` of ``n`` rows, evenly spaced in row order, for drawing only.

    A scatter of every sample costs time linear in the samples and shows nothing more once the
    points overlap; the figures of a large file draw every ``ceil(n / limit)``-th row.
    """
    return np.arange(0, n, max(1, -(-n // max(int(limit), 1))))


def fixed_margins(fig, left=0.75, right=0.15, bottom=0.55, top=0.4, wspace=0.3, hspace=0.5):
    """Fix ``fig``'s subplot margins in inches (``left`` ... ``top``; ``wspace``/``hspace`` as shares of a panel)
    and keep them: :func:`save_figure` then lays nothing out again. Returns ``fig``.

    A constrained or tight layout measures every tick label of every panel (twice for a constrained one) each
    time the figure is saved; with a log axis that took most of a report figure's CPU. Fixed margins in inches
    fit the report's labels at any figure size.
    """
    from matplotlib.layout_engine import PlaceHolderLayoutEngine
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h, wspace=wspace,
                        hspace=hspace)
    fig.set_layout_engine(PlaceHolderLayoutEngine(adjust_compatible=True, colorbar_gridspec=True))
    return fig


def save_figure(fig, path) -> Path:
    """Write ``fig`` as a PNG (120 dpi, tight layout; parent folders created), close it, return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if fig.get_layout_engine() is None:
        fig.tight_layout()
    fig.savefig(path, dpi=120)
    pyplot().close(fig)
    return path


def fig9a_speed_vs_position_by_voltage(df: pd.DataFrame, path, load_kg: float = 0.0, direction: int = 1) -> Path:
    """Paper Fig. 9(a): load-free speed against position for each V0."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    sel = df[np.isclose(df[dataio.LOAD], load_kg) & (df[dataio.DIRECTION] == direction)]
    for V, g in sorted(sel.groupby(dataio.VOLTAGE), key=lambda x: x[0]):
        ax.plot(g[dataio.POSITION] * 1e3, np.abs(g[dataio.SPEED]) * 1e3, label=f"V0 = {V:g} V")
    ax.set_xlabel("position [mm]")
    ax.set_ylabel("speed [mm/s]")
    ax.set_title(f"Speed vs position, load {load_kg:g} kg, direction {direction:+d} (cf. paper Fig. 9a)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return save_figure(fig, path)


def fig9b_speed_vs_position_by_load(df: pd.DataFrame, path, V0_V: float | None = None, direction: int = 1) -> Path:
    """Paper Fig. 9(b): speed against position for each horizontal load at one V0."""
    plt = pyplot()
    V0_V = float(df[dataio.VOLTAGE].max()) if V0_V is None else V0_V
    fig, ax = plt.subplots(figsize=(7, 4.2))
    sel = df[np.isclose(df[dataio.VOLTAGE], V0_V) & (df[dataio.DIRECTION] == direction)]
    for L, g in sorted(sel.groupby(dataio.LOAD), key=lambda x: x[0]):
        ax.plot(g[dataio.POSITION] * 1e3, np.abs(g[dataio.SPEED]) * 1e3, label=f"load {L:+.2f} kg")
    ax.set_xlabel("position [mm]")
    ax.set_ylabel("speed [mm/s]")
    ax.set_title(f"Speed vs position at V0 = {V0_V:g} V, direction {direction:+d} (cf. paper Fig. 9b)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    return save_figure(fig, path)


def fig9c_fit(df: pd.DataFrame, load_kg: float = 0.0) -> dict:
    """Line fit of |speed| against the tip velocity amplitude omega*U_w (no-load runs, evaluated samples).

    Returns slope ``k0`` (the paper's proportional coefficient), intercept [m/s], R^2 and the points.
    """
    if "tip_velocity_amp_m_s" not in df:
        raise KeyError("Fig. 9c needs the vibrometer column 'tip_velocity_amp_m_s'")
    sel = df[np.isclose(df[dataio.LOAD], load_kg)].reset_index(drop=True)
    mask = evaluation_mask(sel)
    x = sel["tip_velocity_amp_m_s"].to_numpy()[mask]
    y = np.abs(sel[dataio.SPEED].to_numpy()[mask])
    A = np.column_stack([x, np.ones_like(x)])
    (k0, b), *_ = np.linalg.lstsq(A, y, rcond=None)
    yhat = A @ np.array([k0, b])
    r2 = 1 - np.sum((y - yhat) ** 2) / np.sum((y - y.mean()) ** 2)
    return {"k0": float(k0), "intercept_m_s": float(b), "r2": float(r2), "n": int(len(x)), "x": x, "y": y}


def fig9c_speed_vs_tip_velocity(df: pd.DataFrame, path, load_kg: float = 0.0) -> tuple[Path, dict]:
    """Paper Fig. 9(c): v_s against omega*U_w with the fitted line, its slope k0 and R^2."""
    plt = pyplot()
    fit = fig9c_fit(df, load_kg)
    fig, ax = plt.subplots(figsize=(6, 4.5))
    ax.plot(fit["x"] * 1e3, fit["y"] * 1e3, ".", ms=2, alpha=0.4, label="samples (no load)")
    xx = np.linspace(fit["x"].min(), fit["x"].max(), 2)
    ax.plot(xx * 1e3, (fit["k0"] * xx + fit["intercept_m_s"]) * 1e3, "r-",
            label=f"fit: k0 = {fit['k0']:.3f}, R$^2$ = {fit['r2']:.3f}")
    ax.set_xlabel(r"tip velocity amplitude $\omega U_w$ [mm/s]")
    ax.set_ylabel("slider speed [mm/s]")
    ax.set_title("Speed vs transverse vibration velocity (cf. paper Fig. 9c)")
    ax.legend()
    ax.grid(alpha=0.3)
    return save_figure(fig, path), {k: v for k, v in fit.items() if k not in ("x", "y")}


def data_speed_label(speed_derived: bool) -> str:
    """How figures name the data's speed: "measured", or "derived from position" when the file had none."""
    return "derived from position" if speed_derived else "measured"


def prediction_vs_measured(run_df: pd.DataFrame, v_pred: np.ndarray, path, title: str,
                           v_pred_alt: np.ndarray | None = None, labels=("predicted", "alternative"),
                           measured: str = "measured") -> Path:
    """Paper Fig. 10: predicted and measured (or derived, ``measured``) speed over position, with the relative error."""
    plt = pyplot()
    s = run_df[dataio.POSITION].to_numpy() * 1e3
    v = run_df[dataio.SPEED].to_numpy()
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 5.5), gridspec_kw={"height_ratios": [2, 1]})
    ax1.plot(s, np.abs(v) * 1e3, "k.", ms=2, label=measured)
    ax1.plot(s, np.abs(v_pred) * 1e3, "b-", label=labels[0])
    if v_pred_alt is not None:
        ax1.plot(s, np.abs(v_pred_alt) * 1e3, "r--", label=labels[1])
    ax1.set_ylabel("speed [mm/s]")
    ax1.set_title(title, fontsize=10)
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    mask = evaluation_mask(run_df.reset_index(drop=True))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = (v_pred - v) / v * 100
    ax2.plot(s[mask], rel[mask], "b.", ms=2)
    if v_pred_alt is not None:
        ax2.plot(s[mask], ((v_pred_alt - v) / v * 100)[mask], "r.", ms=2)
    ax2.axhline(5, color="gray", ls=":")
    ax2.axhline(-5, color="gray", ls=":")
    ax2.set_ylabel("rel. error [%]")
    ax2.set_xlabel("position [mm]")
    ax2.grid(alpha=0.3)
    return save_figure(fig, path)


def steady_comparison(tables: dict, path) -> Path:
    """Predicted against co-simulated steady speed, one panel per comparison, with the error range."""
    plt = pyplot()
    n = len(tables)
    ncol = min(n, 3)
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 4.4 * nrow), squeeze=False, layout="constrained")
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    fig.suptitle("Predictor against co-simulation: steady speed at each grid point")
    for ax, (key, df) in zip(axes.flat, tables.items()):
        moving = df.v_cosim_m_s.abs() > 5e-3
        x = df.v_cosim_m_s[moving].abs() * 1e3
        y = df.v_pred_m_s[moving].abs() * 1e3
        ax.plot(x, y, ".", ms=3)
        lim = [0, max(x.max(), y.max()) * 1.05]
        ax.plot(lim, lim, "k-", lw=0.8)
        e = df.rel_error[moving].abs()
        ax.set_title(f"{key.replace('_', ' ')}\nmax |err| {e.max():.1%}, rms {np.sqrt(np.mean(e ** 2)):.1%}",
                     fontsize=10)
        ax.set_xlabel("co-simulation steady speed [mm/s]")
        ax.set_ylabel("predictor steady speed [mm/s]")
        ax.grid(alpha=0.3)
    return save_figure(fig, path)
