"""The result of a co-simulation run, the same type for the fmpy master and the in-process engine."""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd



#: SI unit -> (factor, unit drawn) for figures: mm and mm/s as in every figure of the project
PLOT_UNITS = {"m": (1e3, "mm"), "m/s": (1e3, "mm/s"), "m/s2": (1e3, "mm/s²")}

class CoSimResult:
    """Time series of a co-simulation: ``.df`` (pandas), ``.units``, ``.to_csv()``, ``.plot()``."""

    def __init__(self, df: pd.DataFrame, units: Mapping[str, str]):
        self.df = df
        self.units = dict(units)
        self.df.attrs["units"] = self.units

    def to_pandas(self) -> pd.DataFrame:
        """The time series (column ``time`` [s] and ``Component.variable``; units in ``.attrs['units']``)."""
        return self.df

    def keys(self):
        return list(self.df.columns)

    def __getitem__(self, key):
        return self.df[key].to_numpy()

    def to_csv(self, path) -> Path:
        """CSV with the unit in every column name, e.g. ``Slider.v [m/s]``."""
        path = Path(path)
        out = self.df.rename(columns={c: f"{c} [{self.units.get(c, '1')}]" for c in self.df.columns})
        path.parent.mkdir(parents=True, exist_ok=True)
        out.to_csv(path, index=False, float_format="%.10g")
        return path

    def plot(self, columns=("Slider.v", "Slider.s"), path=None, title: str | None = None):
        """Figure of ``columns`` over time (saved as PNG at ``path`` when given).

        Lengths are drawn in mm (below 0.1 mm, e.g. tip amplitudes, in um), speeds in mm/s (:data:`PLOT_UNITS`); the files keep SI.
        """
        import matplotlib.pyplot as plt  # plotting is optional for simulation users
        fig, axes = plt.subplots(len(columns), 1, sharex=True, figsize=(7, 2.2 * len(columns) + 0.5),
                                 layout="constrained")
        for ax, col in zip(np.atleast_1d(axes), columns):
            k, unit = PLOT_UNITS.get(self.units.get(col, ""), (1.0, self.units.get(col, "")))
            if unit == "mm" and float(np.nanmax(np.abs(self.df[col]))) < 1e-4:
                k, unit = 1e6, "µm"   # tip amplitudes
            ax.plot(self.df["time"], self.df[col] * k)
            ax.set_ylabel(f"{col} [{unit or '-'}]")
            ax.ticklabel_format(axis="y", useOffset=False)
            ax.grid(alpha=0.3)
        np.atleast_1d(axes)[-1].set_xlabel("time [s]")
        fig.suptitle(title or f"co-simulation: {', '.join(columns)} over time")
        if path is not None:
            fig.savefig(path, dpi=120)
            plt.close(fig)
        return fig
