"""The result of a co-simulation run, the same type for the fmpy master and the in-process engine."""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd


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

    def plot(self, columns=("Slider.v", "Slider.s"), path=None):
        """Figure of ``columns`` over time (saved as PNG at ``path`` when given)."""
        import matplotlib.pyplot as plt  # plotting is optional for simulation users
        fig, axes = plt.subplots(len(columns), 1, sharex=True, figsize=(7, 2.2 * len(columns)))
        for ax, col in zip(np.atleast_1d(axes), columns):
            ax.plot(self.df["time"], self.df[col])
            ax.set_ylabel(f"{col} [{self.units.get(col, '')}]")
        np.atleast_1d(axes)[-1].set_xlabel("time [s]")
        fig.tight_layout()
        if path is not None:
            fig.savefig(path, dpi=120)
            plt.close(fig)
        return fig
