"""A logged channel that relabels the plan's inputs run by run is listed and offered no hypothesis: the flatness
test, the cells' chi-square written out, the smallest set of cells, and the channel record, signals and note."""

import numpy as np
import pandas as pd
from scipy import stats

V0S = (220.0, 255.0, 290.0, 324.0)
LOADS = (-0.09, -0.06, -0.03, 0.0, 0.03, 0.06, 0.09)


def plan_frame(n=120, seed=0):
    """56 runs of ``n`` samples: every V0 and load, forward then backward at each setting (runs in a shuffled order
    of settings), and ``noise`` (standard normal per sample) and ``eps`` (standard normal per run) to build from."""
    rng = np.random.default_rng(seed)
    settings = [(V, L) for V in V0S for L in LOADS]
    order = rng.permutation(len(settings))
    rows, k = [], 0
    for i in order:
        V, L = settings[i]
        for d in (1, -1):
            k += 1
            rows.append(pd.DataFrame({"run": k, "time_s": 10.0 * k + 0.001 * np.arange(n), "voltage_V": V,
                                      "load_kg": L, "direction": d, "position_m": 0.001 * np.arange(n) * d,
                                      "speed_m_s": 0.1 * d, "noise": rng.standard_normal(n),
                                      "eps": rng.standard_normal()}))
    return pd.concat(rows, ignore_index=True)


def q_of(df, name, cols):
    """The chi-square statistic, written out: run means about their cell's weighted mean over the run mean's noise
    variance (first differences within runs, over the run's sample count), and its degrees of freedom."""
    runs = df.groupby("run", sort=False)
    dx = runs[name].diff().dropna().to_numpy()
    noise = np.sum(dx ** 2) / (2 * dx.size)
    tab = runs.agg(m=(name, "mean"), n=(name, "size"), **{c: (c, "first") for c in cols})
    tab["w"] = tab["n"] / noise
    centre = tab.groupby(list(cols)).apply(lambda g: np.sum(g["w"] * g["m"]) / np.sum(g["w"]))
    c = np.array([centre[tuple(r)] if len(cols) > 1 else centre[r[0]] for r in tab[list(cols)].to_numpy()])
    return float(np.sum(tab["w"] * (tab["m"] - c) ** 2)), len(tab) - len(centre)


def test_a_phase_meter_follows_the_direction_and_v0():
    from l1b2.closeloop.relabels import follows_plan
    df = plan_frame()
    d, V = df["direction"], df["voltage_V"]
    df["phase_deg"] = np.round(d * (90 + 2.0 * (V / 324) ** 2) + 0.1 * df["noise"], 2)
    assert follows_plan(df, "phase_deg") == ("voltage_V", "direction")
    # its sign alone is a relabelled direction, its size alone a relabelled V0
    df["sign_deg"] = 90 * d + 0.1 * df["noise"]
    df["size_deg"] = 90 + 2.0 * (V / 324) ** 2 + 0.1 * df["noise"]
    assert follows_plan(df, "sign_deg") == ("direction",)
    assert follows_plan(df, "size_deg") == ("voltage_V",)
    # a balance reading the hung weight's size: the load's cells (7, before the 8 of V0 and the direction)
    df["tray_g"] = 240 - 1000 * df["load_kg"].abs() + 0.3 * df["noise"]
    assert follows_plan(df, "tray_g") == ("load_kg",)
    # a reading with no noise at all follows its cells exactly
    df["exact"] = 2.0 * d + V / 100
    assert follows_plan(df, "exact") == ("voltage_V", "direction")
    # the model's own inputs are never relabels of each other
    df["frequency_Hz"] = 40000 + 10 * V
    df["temperature_C"] = 25 + V / 100
    assert follows_plan(df, "frequency_Hz") == () and follows_plan(df, "temperature_C") == ()


def test_the_cells_chi_square_decides_written_out():
    from l1b2.closeloop.relabels import RELABEL_P, follows_plan
    df = plan_frame(seed=3)
    sigma = 0.05
    seen = set()
    for scale in np.r_[0.0, np.linspace(0.002, 0.006, 41), 0.05]:   # fine steps across the threshold
        name = f"supply_{scale}"
        df[name] = df["voltage_V"] / 10 + scale * df["eps"] + sigma * df["noise"]
        q, dof = q_of(df, name, ["voltage_V"])
        want = stats.chi2.sf(q, dof) > RELABEL_P
        assert (follows_plan(df, name) == ("voltage_V",)) == want, (scale, q, dof)
        seen.add(want)
    assert seen == {True, False}   # both sides of the threshold exercised


def test_structure_within_runs_drift_and_pairs_are_not_relabels():
    from l1b2.closeloop.relabels import follows_plan
    df = plan_frame(seed=5)
    t_run = df["time_s"] - df.groupby("run")["time_s"].transform("min")
    V = df["voltage_V"]
    # settling within each run (a filter after each change): structure beyond white noise
    df["settling"] = V / 10 + 3.0 * np.exp(-t_run / 0.02) + 0.05 * df["noise"]
    # a drift between runs of the same cell
    df["drifting"] = V / 10 + 0.02 * df["run"] + 0.05 * df["noise"]
    # a state shared by each forward/backward pair (the cells of V0 and the load are those pairs)
    df["pair_state"] = df.groupby(["voltage_V", "load_kg"])["eps"].transform("first") + 0.05 * df["noise"]
    # a sensor whose samples vary within runs far more than its run means do
    df["white"] = V / 1000 + 1.0 * df["noise"]
    for name in ("settling", "drifting", "pair_state", "white"):
        assert follows_plan(df, name) == (), name
    assert follows_plan(df.assign(flat=1.0), "flat") == ()


def test_the_channel_record_signals_and_note():
    from l1b2.closeloop.candidates import channels_of
    from l1b2.closeloop.evidence import channels_considered
    from l1b2.closeloop.runlevel import run_signals
    df = plan_frame(seed=7)
    df["phase_deg"] = df["direction"] * (90 + 2.0 * (df["voltage_V"] / 324) ** 2) + 0.1 * df["noise"]
    df["drifting"] = df["voltage_V"] / 10 + 0.02 * df["run"] + 0.05 * df["noise"]
    df = df.drop(columns=["noise", "eps"])
    ch = {c["name"]: c for c in channels_of(df)}
    assert ch["phase_deg"]["kind"] == "relabel" and ch["phase_deg"]["follows"] == ("voltage_V", "direction")
    assert ch["drifting"]["kind"] == "logged" and "follows" not in ch["drifting"]
    names = {s["channel"] for s in run_signals(df, channels_of(df))}
    assert "drifting" in names and "phase_deg" not in names
    rows = {r["channel"]: r for r in channels_considered(channels_of(df), [], 0.01, 0.0, set())}
    assert "voltage_V and direction" in rows["phase_deg"]["note"] and not rows["phase_deg"]["significant"]
    assert rows["phase_deg"]["follows"] == ["voltage_V", "direction"] and "follows" not in rows["drifting"]


def test_a_relabel_gets_no_hypothesis():
    import l1b2.predictor.effects as fx
    from l1b2.closeloop.candidates import channels_of
    df = plan_frame(seed=9)
    df["phase_deg"] = df["direction"] * (90 + 2.0 * (df["voltage_V"] / 324) ** 2) + 0.1 * df["noise"]
    df["drifting"] = df["voltage_V"] / 10 + 0.02 * df["run"] + 0.05 * df["noise"]
    chans = channels_of(df.drop(columns=["noise", "eps"]))
    train = fx.TrainingSummary(m_s=0.02, time_range=(0.0, 600.0), position_range=(-0.02, 0.02),
                               voltage_median=270.0, ranges={"load_abs": 0.09}, channels=chans)
    hyps = fx.family("channel").grid(train)
    fams = {h["spec"]["channel"] if isinstance(h, dict) else h.spec["channel"] for h in hyps}
    assert "drifting" in fams and "phase_deg" not in fams
