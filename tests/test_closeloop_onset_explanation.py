"""What explains the rests cut before TRAIN's onsets beyond the plan's inputs (``closeloop.evidence``): the least
squares on the inputs' run signals and the rank test written out, the cases that explain nothing, and the trace."""
import numpy as np
import pandas as pd
import pytest
from scipy import stats

from l1b2.closeloop.candidates import channels_of
from l1b2.closeloop.evidence import ONSET_MIN_RUNS, onset_explanation, with_onset


def _session(n_runs=36, n=40, seed=3):
    """Runs at three V0, three loads and both directions, with a logged relay delay setting (ms) and a noise
    channel, each constant within a run; the delay each run rests before it moves: half its relay setting, plus 10 ms
    when its load opposes the motion, plus a jitter of 4 ms."""
    rng = np.random.default_rng(seed)
    parts, delays = [], {}
    for r in range(n_runs):
        d, m, V = (1.0 if r % 2 == 0 else -1.0), (-0.05, 0.0, 0.05)[(r // 2) % 3], (220.0, 272.0, 324.0)[r % 3]
        relay = float(rng.uniform(0.0, 60.0))
        delays[r + 1] = max(0.0, 0.5e-3 * relay + (0.01 if d * m > 0 else 0.0) + float(rng.normal(0.0, 4e-3)))
        t = 5.0 * r + 1e-3 * np.arange(n)
        parts.append(pd.DataFrame({"run": r + 1, "time_s": t, "position_m": d * 1e-3 * np.arange(n),
                                   "speed_m_s": d * 0.1, "voltage_V": V, "load_kg": m, "direction": d,
                                   "relay_ms": round(relay, 1), "noise_u": float(rng.standard_normal())}))
    return pd.concat(parts, ignore_index=True), delays


def _record(delays, cut_min_s=2e-3):
    per_run = [[r, int(d / 1e-3), d, 1] for r, d in delays.items() if d >= cut_min_s]
    ds = [p[2] for p in per_run]
    return {"runs": len(per_run), "of_runs": len(delays), "cut": True, "per_run": per_run,
            "median_delay_s": float(np.median(ds)) if ds else None, "max_delay_s": max(ds) if ds else None}


def test_the_residual_after_the_inputs_and_the_rank_test_written_out():
    df, delays = _session()
    rec = _record(delays)
    runs = pd.unique(df["run"])
    y = np.array([d if d >= 2e-3 else 0.0 for d in (delays[r] for r in runs)])
    g = df.groupby("run", sort=False)
    V, m, d = (g[c].mean().to_numpy() for c in ("voltage_V", "load_kg", "direction"))
    X = np.column_stack([np.ones(len(y)), V, d * m, np.abs(m), d])
    resid = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    tests = {c: stats.spearmanr(g[c].mean().to_numpy(), resid) for c in ("relay_ms", "noise_u")}
    out = onset_explanation(df, rec, channels_of(df), alpha=0.01)
    assert out["signal"] == "relay_ms" and out["regressor"] == "relay_ms" and out["runs"] == rec["runs"]
    k = out["signals_tested"]
    assert k >= 2                                   # the two channels and the session clock's run mean
    assert out["rho"] == pytest.approx(tests["relay_ms"].statistic, rel=1e-12)
    assert out["p_value"] == pytest.approx(min(1.0, k * tests["relay_ms"].pvalue), rel=1e-9, abs=0.0)
    assert 0.5 < out["rho"] < 0.99 and 1e-20 < out["p_value"] < 1e-4   # not 0: the Bonferroni factor tells


def test_rests_the_inputs_explain_or_too_few_runs_explain_nothing():
    df, delays = _session()
    chans = channels_of(df)
    # the rest only where the load opposes the motion (a heavier start): nothing beyond the inputs
    g = df.groupby("run")
    opposing = (g["direction"].first() * g["load_kg"].first() > 0).to_dict()
    by_load = {r: (0.01 if opposing[r] else 0.0) for r in delays}
    assert onset_explanation(df, _record(by_load), chans, alpha=0.01) is None
    # fewer than ONSET_MIN_RUNS runs cut
    few = dict(sorted(delays.items(), key=lambda kv: -kv[1])[:ONSET_MIN_RUNS - 1])
    assert onset_explanation(df, _record({r: few.get(r, 0.0) for r in delays}), chans, alpha=0.01) is None
    assert onset_explanation(df, None, chans, alpha=0.01) is None
    # ONSET_MIN_RUNS - 1 rests, with a channel that ranks the residual exactly: still nothing
    two = {r: (0.02 if r in (1, 2) else 0.0) for r in delays}
    rec = _record(two)
    g = df.groupby("run", sort=False)
    V, m, d = (g[c].mean().to_numpy() for c in ("voltage_V", "load_kg", "direction"))
    X = np.column_stack([np.ones(len(V)), V, d * m, np.abs(m), d])
    y = np.array([two[r] for r in pd.unique(df["run"])])
    resid = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    ranked = df.assign(ranked_u=df["run"].map(dict(zip(pd.unique(df["run"]), resid))))
    assert onset_explanation(ranked, rec, channels_of(ranked), alpha=0.01) is None
    assert onset_explanation(ranked, {**rec, "runs": ONSET_MIN_RUNS}, channels_of(ranked), 0.01)["signal"] == "ranked_u"


def test_the_explaining_signal_is_traced_second_and_named():
    df, delays = _session()
    rec = _record(delays)
    diag = with_onset({"traced_to": ["voltage", "relay_ms", "load"], "message": "missing effects: x"}, rec, df,
                      channels_of(df), 0.01)
    assert diag["traced_to"] == ["rest_before_onset", "relay_ms", "voltage", "load"]
    assert "the rests follow relay_ms beyond the plan's inputs" in diag["message"]
    assert diag["message"].endswith(")") and diag["rest_before_onset"]["explained_by"]["signal"] == "relay_ms"
    # without the frame, as before: the stage first, nothing explained
    plain = with_onset({"traced_to": ["voltage"], "message": "m"}, rec)
    assert plain["traced_to"] == ["rest_before_onset", "voltage"] and "explained_by" not in plain["rest_before_onset"]


def test_a_monotone_transform_ties_with_its_column_and_the_column_listed_first_is_named():
    df, delays = _session()
    df = df.assign(relay_ms=df["relay_ms"].round(0))          # a register of whole ms: runs share values
    assert df.groupby("run")["relay_ms"].first().duplicated().any()
    # listed after relay_ms, the same ranks; a round-off in its last bits in some runs parts no tie
    df = df.assign(ln_relay_ms=np.log(df["relay_ms"] + 1.0) * (1.0 + 2e-16 * (df["run"] % 2)))
    out = onset_explanation(df, _record(delays), channels_of(df), alpha=0.01)
    assert out["signal"] == "relay_ms"
    swapped = df[[c for c in df.columns if c != "relay_ms"] + ["relay_ms"]]
    assert onset_explanation(swapped, _record(delays), channels_of(swapped), alpha=0.01)["signal"] == "ln_relay_ms"
