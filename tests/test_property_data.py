"""Property: a malformed data file is refused in one line with nothing written, or gives the clean file's metrics.

Hypothesis draws a malformation of a valid file - a unit or scale mistake in
any numeric column (including the ones inside the per-column ranges: load
in N / lb / x10, temperature in degF, time x100), the load's sign flipped,
one run's voltage zeroed, one run's direction flipped, a clock jump inside a
run, a junk cell, a duplicate sidecar key - or a harmless change of form
(CRLF line ends, spaces around cells, a byte-order mark, columns in another
order, an extra column, another spelling of the same numbers). Every file
goes through ``l1b2 identify`` (the fit replaced by a sentinel) and must be
either refused (exit 2, exactly one line ``l1b2: error: ...``, no output
folder, nothing else new) or accepted; an accepted file must give exactly
the clean file's error metrics of a fixed Eq. 29 predictor (one-step,
evaluated by the data format's rules). So no wrong file is believed, and
no harmless one refused for its form.
"""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from l1b2.cli import main as cli_main
from l1b2.data.measurements import evaluation_mask, load_measurements
from l1b2.data.metrics import speed_metrics
from l1b2.errors import IdentificationError
from l1b2.predictor import model as pr
from l1b2.predictor.model import example_params
from l1b2.predictor.simulate import design_grid, simulate_dataset

M_S = 0.1
SENTINEL = "FIT-REACHED"
PARAMS = example_params(3)


def _base() -> pd.DataFrame:
    df = simulate_dataset(PARAMS, design_grid(voltages=(220.0, 324.0), loads=(-0.05, 0.0, 0.05)), M_S,
                          noise_std=1e-4, seed=5)
    return df.assign(frequency_Hz=48500.0, temperature_C=25.0)


BASE = _base()
RUNS = list(pd.unique(BASE["run"]))

#: unit and scale mistakes: column -> factors (each must be refused)
SCALES = {
    "time_s": (1e3, 100.0, 1e-3),
    "position_m": (10.0, 100.0, 1e3),
    "voltage_V": (1e3, 1e-3),
    "load_kg": (1e3, 9.80665, 1 / 0.45359237, 10.0, -1.0),
    "speed_m_s": (1e3, 1e-3, -1.0),
    "frequency_Hz": (1e-3, 0.1),
}


def _metrics(df: pd.DataFrame) -> dict:
    """One-step metrics of the fixed predictor PARAMS on ``df`` (data-format evaluation rules)."""
    v = df["speed_m_s"].to_numpy()
    t = df["time_s"].to_numpy()
    same = np.r_[False, df["run"].to_numpy()[1:] == df["run"].to_numpy()[:-1]]
    pred = np.full(v.size, np.nan)
    k = np.flatnonzero(same)
    pred[k] = pr.one_step(PARAMS, v[k - 1], df["position_m"].to_numpy()[k - 1], df["voltage_V"].to_numpy()[k - 1],
                          df["load_kg"].to_numpy()[k - 1], df["direction"].to_numpy()[k - 1], t[k] - t[k - 1], M_S)
    return speed_metrics(pred, v, evaluation_mask(df))


CLEAN = _metrics(BASE)


@st.composite
def malformed(draw):
    """(kind, csv text, sidecar text, must_refuse)."""
    df = BASE.copy()
    side = json.dumps({"slider_mass_kg": M_S})
    kind = draw(st.sampled_from(["scale", "zero_voltage", "flip_direction", "clock_jump", "junk", "dup_key",
                                 "degF", "benign"]))
    refuse = True
    if kind == "scale":
        col = draw(st.sampled_from(sorted(SCALES)))
        df[col] = df[col] * draw(st.sampled_from(SCALES[col]))
        kind = f"{col} x"
    elif kind in ("zero_voltage", "flip_direction"):
        # a run whose load does not pull against its (new) direction: its speed contradicts the inputs
        cand = [r for r in RUNS if (df.loc[df.run == r, "load_kg"].iloc[0] * df.loc[df.run == r, "direction"].iloc[0]
                                    >= 0)]
        r = draw(st.sampled_from(cand))
        m = df["run"] == r
        if kind == "zero_voltage":
            cand0 = [q for q in RUNS if df.loc[df.run == q, "load_kg"].iloc[0] == 0.0]
            m = df["run"] == draw(st.sampled_from(cand0))
            df.loc[m, "voltage_V"] = 0.0
        else:
            df.loc[m, "direction"] = -df.loc[m, "direction"]
    elif kind == "clock_jump":
        r = draw(st.sampled_from(RUNS))
        idx = df.index[df["run"] == r]
        at = idx[draw(st.integers(1, len(idx) - 1))]
        df.loc[at:, "time_s"] += draw(st.sampled_from([5.0, 1e3, 1e6]))
    elif kind == "degF":
        df["temperature_C"] = df["temperature_C"] * 1.8 + 32.0
    elif kind == "junk":
        col = draw(st.sampled_from(["time_s", "position_m", "voltage_V", "direction", "load_kg", "speed_m_s"]))
        row = draw(st.integers(0, len(df) - 1))
        df[col] = df[col].astype(object)
        df.loc[row, col] = draw(st.sampled_from(["", "nan", "inf", "abc", "1,5", "1e400"]))
    elif kind == "dup_key":
        side = '{"slider_mass_kg": %r, "slider_mass_kg": %r}' % (M_S, draw(st.sampled_from([M_S, 0.22, 100.0])))
    else:
        refuse = False
    text = df.to_csv(index=False, lineterminator="\n", float_format="%.17g")
    if kind == "benign":
        form = draw(st.sampled_from(["crlf", "spaces", "bom", "reorder", "extra", "exponent", "trailing_newlines"]))
        kind = f"benign {form}"
        if form == "crlf":
            text = text.replace("\n", "\r\n")
        elif form == "spaces":
            text = "\n".join(",".join(f" {c} " for c in ln.split(",")) if ln else ln for ln in text.split("\n"))
        elif form == "bom":
            text = "\ufeff" + text
        elif form == "reorder":
            cols = list(df.columns)
            order = draw(st.permutations(cols))
            text = df[list(order)].to_csv(index=False, lineterminator="\n", float_format="%.17g")
        elif form == "extra":
            text = df.assign(note="x", gain=1.5).to_csv(index=False, lineterminator="\n", float_format="%.17g")
        elif form == "exponent":
            text = df.to_csv(index=False, lineterminator="\n", float_format="%.17e")
        else:
            text += "\n\n"
    return kind, text, side, refuse


def _sentinel_fit(self, *args, **kwargs):
    raise IdentificationError(SENTINEL)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(malformed())
def test_malformed_files_are_refused_in_one_line_or_give_the_clean_metrics(case):
    from l1b2.ident.estimator import PredictorIdentifier
    kind, text, side, must_refuse = case
    with tempfile.TemporaryDirectory() as td:
        d = Path(td)
        (d / "data.csv").write_text(text, encoding="utf-8", newline="")
        (d / "data.json").write_text(side)
        before = sorted(p.name for p in d.iterdir())
        err = io.StringIO()
        real = PredictorIdentifier.fit
        PredictorIdentifier.fit = _sentinel_fit
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                code = cli_main(["identify", "--train", str(d / "data.csv"), "--out", str(d / "out")])
        finally:
            PredictorIdentifier.fit = real
        msg = err.getvalue()
        assert code == 2 and msg.count("\n") == 1 and msg.startswith("l1b2: error:"), (kind, code, msg)
        assert sorted(p.name for p in d.iterdir()) == before, (kind, msg)   # nothing written
        accepted = SENTINEL in msg
        if must_refuse:
            assert not accepted, f"{kind}: accepted"
        if accepted:
            meas = load_measurements(d / "data.csv")
            got = _metrics(meas.df)
            assert got == CLEAN, (kind, got, CLEAN)


def test_the_clean_file_is_accepted_with_its_metrics(tmp_path):
    path = tmp_path / "data.csv"
    BASE.to_csv(path, index=False, float_format="%.17g")
    (tmp_path / "data.json").write_text(json.dumps({"slider_mass_kg": M_S}))
    meas = load_measurements(path)
    assert meas.meta["unusual_units"] == []
    assert _metrics(meas.df) == CLEAN and CLEAN["n_samples"] > 100
