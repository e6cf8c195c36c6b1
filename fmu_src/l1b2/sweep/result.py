"""The result of a study (:class:`SweepResult`): the table, its summary and sensitivities, files and plots."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pandas as pd

from ..jsonio import dumps
from .analysis import sobol_indices, src_ranking, summarize
from .plots import output_name
from .sampling import parameter_columns
from .spec import OPERATING, StudySpec
from .tasks import TaskContext, output_columns

SAMPLES_FILE = "samples.parquet"


def column_units(table: pd.DataFrame, spec: StudySpec, ctx: TaskContext) -> dict[str, str]:
    """Unit of every numeric column of the table (``"1"`` for counts, ids and flags)."""
    units = {col: unit for col, unit in OPERATING.values()}
    units.update({p.name: p.unit for p in spec.parameters})
    units.update(output_columns(ctx))
    return {c: units.get(c, "1") for c in table.columns if c not in ("block", "status", "error")}


def to_arrow(table: pd.DataFrame, spec: StudySpec, ctx: TaskContext):
    """The table as a ``pyarrow.Table`` with each column's unit and the study in the schema metadata."""
    import pyarrow as pa
    t = pa.Table.from_pandas(table, preserve_index=False)
    units = column_units(table, spec, ctx)
    fields = [f.with_metadata({"unit": units[f.name]}) if f.name in units else f for f in t.schema]
    meta = {**(t.schema.metadata or {}), b"l1b2.study": json.dumps(asdict(spec), default=str).encode(),
            b"l1b2.fingerprint": spec.fingerprint().encode()}
    return pa.Table.from_arrays(t.columns, schema=pa.schema(fields, metadata=meta))


class SweepResult:
    """A finished study: ``.table`` (one row per sample: ids, operating point, parameters, outputs,
    ``status``, ``error``), ``.summary``, ``.sensitivity`` (SRC), ``.sobol`` (Saltelli designs),
    ``.save(dir)`` and ``.plot(dir)``."""

    def __init__(self, table: pd.DataFrame, spec: StudySpec, ctx: TaskContext, info: dict | None = None):
        self.table = table
        self.spec = spec
        self.ctx = ctx
        self.info = dict(info or {})
        self.outputs = list(output_columns(ctx))
        self.summary = summarize(table, self.outputs)
        self.sensitivity = src_ranking(table, self.outputs)
        self.sobol = sobol_indices(table, self.outputs, seed=spec.seed) if spec.design == "saltelli" else None

    @property
    def failed(self) -> pd.DataFrame:
        """The samples whose simulation raised, with their messages."""
        return self.table[self.table["status"] != "ok"]

    def to_dict(self) -> dict:
        """JSON-able report: the study, counts, the summary and the rankings."""
        def records(df):
            return [] if df is None else json.loads(df.to_json(orient="records"))
        return {"study": asdict(self.spec), "fingerprint": self.spec.fingerprint(),
                "samples": int(len(self.table)), "failed": int(len(self.failed)),
                "failures": records(self.failed[["sample_id", "error"]].head(20)),
                "parameters": parameter_columns(self.table), "outputs": self.outputs,
                "units": column_units(self.table, self.spec, self.ctx),
                "summary": records(self.summary), "sensitivity_src": records(self.sensitivity),
                "sobol": records(self.sobol), **self.info}

    def save(self, out_dir, plots: bool = True) -> dict[str, Path]:
        """Write ``samples.parquet``, ``summary.csv``, ``sensitivity.csv`` (+ ``sobol.csv``), ``study.json``
        and (``plots``) the PNGs into ``out_dir``; returns the paths by name."""
        import pyarrow.parquet as pq
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {"samples": out / SAMPLES_FILE, "summary": out / "summary.csv",
                 "sensitivity": out / "sensitivity.csv", "report": out / "study.json"}
        pq.write_table(to_arrow(self.table, self.spec, self.ctx), paths["samples"])
        self.summary.to_csv(paths["summary"], index=False, float_format="%.6g")
        self.sensitivity.to_csv(paths["sensitivity"], index=False, float_format="%.6g")
        if self.sobol is not None:
            paths["sobol"] = out / "sobol.csv"
            self.sobol.to_csv(paths["sobol"], index=False, float_format="%.6g")
        if plots:
            paths.update(self.plot(out))
        report = self.to_dict()
        report["files"] = {k: str(v) for k, v in paths.items()}
        paths["report"].write_text(dumps(report))
        return paths

    def plot(self, out_dir) -> dict[str, Path]:
        """PNG figures: output distributions, sensitivity ranking, operating map (several points)."""
        from . import plots
        out = Path(out_dir)
        figs = {"fig_outputs": plots.output_distributions(self, out / "sweep_outputs.png"),
                "fig_sensitivity": plots.sensitivity_bars(self, out / "sweep_sensitivity.png")}
        if self.table["op_id"].nunique() > 1:
            figs["fig_operating_map"] = plots.operating_map(self, out / "sweep_operating_map.png")
        return {k: v for k, v in figs.items() if v is not None}

    def report_lines(self) -> list[str]:
        """A few lines for the terminal: per operating point the mean speed's p5/p50/p95, stalls, top parameter."""
        lines = []
        s = self.summary
        key = "mean_speed_m_s" if "mean_speed_m_s" in self.outputs else self.outputs[0]
        for op_id, g in s.groupby("op_id", sort=True):
            op = g.iloc[0]
            head = (f"  V0 {op['V0_V']:g} V, load {op['load_kg']:+g} kg, dir {int(op['direction']):+d}, "
                    f"{op['frequency_Hz']:g} Hz, {op['temperature_degC']:g} degC:")
            row = g[g["output"] == key]
            if len(row) and np.isfinite(row["p50"].iloc[0]):
                r = row.iloc[0]
                scale, unit = (1e3, "mm/s") if key.endswith("_m_s") else (1.0, key.rsplit("_", 1)[-1])
                head += (f" {output_name(key)} p5 {r['p5'] * scale:.1f}, p50 {r['p50'] * scale:.1f}, "
                         f"p95 {r['p95'] * scale:.1f} {unit} (n={int(r['n'])})")
            st = g[g["output"] == "stalled"]
            if len(st):
                head += f", stalled {st['mean'].iloc[0]:.0%}"
            rank = self.sensitivity
            top = rank[(rank["op_id"] == op_id) & (rank["output"] == key) & (rank["rank"] == 1)]
            if len(top):
                head += f"; most influential: {top['parameter'].iloc[0]} (SRC {top['src'].iloc[0]:+.2f}, " \
                        f"R^2 {top['r2'].iloc[0]:.2f})"
            lines.append(head)
        if len(self.failed):
            lines.append(f"  {len(self.failed)} sample(s) failed, e.g. sample {int(self.failed['sample_id'].iloc[0])}: "
                         f"{self.failed['error'].iloc[0]}")
        return lines

