#!/usr/bin/env python
"""The close loop's command line on valid but unusual rig data: columns and plans a real rig may log, all legal
per the data format (``docs/reference/data-format.md``).

Every variant starts from one clean realistic case (``bench/blind_effects.py clean SEED``: the realistic world's
72-run plan, TRAIN 56 runs, TEST the 16 runs at |load| 0.05 kg) or, for the ``effect_*`` variants, from the tenth
audit's ``bar_crown_track`` case at the same seed (``bench/blind_effects_tenth.py``; its channel
``track_offset_mm`` carries a real effect). A variant changes copies of TRAIN and TEST (the sidecars are copied
as they are) and runs ``python -m l1b2.cli close-loop --train --test --out --no-plots --quiet --workers 0`` on
them in a subprocess. Each extra column's random values come from their own stream of ``SEED`` and the variant.

Variants (the extra columns are logged in TRAIN and TEST alike unless said otherwise):

* ``clean`` / ``effect`` -- the two cases as they are (written back by pandas): the controls.
* ``noise16`` -- 16 channels ``aux_00 .. aux_15`` of white noise per sample (N(0, 1), 4 decimals).
* ``noise8_run`` -- 8 channels ``setting_0 .. setting_7``, each a random level per run (N(0, 1)) plus 1 % noise
  per sample: settings or slow sensors unrelated to the motor.
* ``int_run3`` -- ``fixture_id`` an integer 1, 2 or 3 drawn per run.
* ``int_sample3`` -- ``daq_status`` an integer 0, 1 or 2 per sample, held for 20-200 samples at a time.
* ``limit_switch`` -- ``limit_switch`` 0/1 per sample: 1 within 1.5 mm of either end of the stroke (a function of
  the position).
* ``const_train`` -- ``ambient_hPa`` 1013.0 in every TRAIN sample and 1009.5 in every TEST sample.
* ``const_all`` -- ``sample_rate_Hz`` 1000 everywhere (a configuration column).
* ``low_rate`` -- ``pressure_kPa`` a random walk sampled and held every 50 ms (a sensor read at 20 Hz whose
  logger repeats the last reading).
* ``twins`` -- ``strain_a`` and ``strain_b`` identical: a random level per run plus noise per sample.
* ``affine_voltage`` -- ``amp_monitor_V`` = voltage_V / 100 + 0.05 (an amplifier's read-back).
* ``affine_load`` -- ``load_N`` = 9.81 load_kg.
* ``huge`` -- ``raw_counts`` white noise of standard deviation 1e9.
* ``tiny`` -- ``leak_A`` white noise of standard deviation 1e-9.
* ``offset_1e9`` -- ``gauge_raw`` 1e9 plus white noise of standard deviation 1.
* ``epoch_clock`` -- ``pc_time_s`` the host's epoch clock: 1764669600 + time_s, 3 decimals (monotonic, huge).
* ``counter`` -- ``sample_counter`` the sample's index over the whole session (TRAIN and TEST in time order).
* ``outlier_run`` -- ``vibration_g`` white noise of 0.01 g, except one TRAIN run where the sensor sat at 50 g.
* ``nan_sparse`` -- ``humidity_pct`` (45 % plus 0.5 % noise, unrelated to the motor) read every 100th sample and
  empty in between, one TEST run with no reading at all, one TRAIN cell ``inf``.
* ``nan_test`` -- ``humidity_pct`` as above but read every sample in TRAIN, and every 25th sample in TEST.
* ``speed_copy`` -- ``laser_speed_m_s`` a second speed sensor: speed_m_s plus its own 1 mm/s noise.
* ``position_copy`` -- ``laser_position_mm`` a second position sensor: 1000 position_m plus 1 um noise.
* ``odd_names`` -- 4 noise channels named ``Ch 3 (V)``, ``T[degC]``, ``x*y`` and ``µstrain``.
* ``short_runs`` -- every 5th TRAIN run and every 4th TEST run cut to its first 3-12 samples (a run stopped early).
* ``two_voltages`` -- TRAIN holds only its runs at 220 V and 324 V; TEST as it is.
* ``effect_noise16`` -- the effect case plus ``noise16``'s 16 channels.
* ``effect_renamed`` -- the effect case with ``track_offset_mm`` renamed ``track offset [mm]``.
* ``quasi_const`` -- ``rate_Hz`` the sample rate the logger computes from its stamps, 1 / (t[k] - t[k-1]) within
  each run: 1000 Hz up to floating-point round-off (relative spread ~1e-13).
* ``test_only`` -- ``probe_mV`` white noise logged in TEST only.
* ``affine_direction`` -- ``relay_ch1`` 1 when the direction is +1, else 0.
* ``nan_test_all`` -- ``humidity_pct`` read every sample in TRAIN, never in TEST (every cell empty).
* ``effect_twins`` -- the effect case with ``track_offset_mm`` logged twice (``track_offset_copy_mm``).
* ``effect_scaled`` / ``effect_tiny`` -- the effect case with ``track_offset_mm`` multiplied by 1e9 / 1e-9 (and
  renamed): the loop standardises channels, so its result should not move.
* ``effect_sparse`` -- the effect case with ``track_offset_mm`` read every 10th sample, empty in between.
* ``noise40`` -- 40 channels of white noise per sample.
* ``one_direction`` -- TRAIN and TEST hold only their runs at direction +1.
* ``single_load`` -- TRAIN holds only its runs at no load (8 runs); TEST as it is.
* ``single_voltage`` -- TRAIN holds only its runs at 324 V; TEST as it is.
* ``test_one_run`` -- TEST holds only its first run.
* ``long_pause`` -- the session spans two days: every stamp after the session's median time moves on by 86 400 s
  (TRAIN and TEST alike; the gap falls between two runs).

Usage: python bench/valid_oddities.py [VARIANT ...] [--seed 1] [--cache DIR] [--work DIR] [--rows FILE]
(no VARIANT: all). Prints one JSON line per variant: rc, the last stderr line, every traced regressor, the added
effects, TEST free-run nrmse before and after [%], whether the report holds a NaN or an infinity, the auxiliary
columns' record and the CPU time of the subprocess (``resource.getrusage`` of the children).
"""
import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from blind_effects import data_dir, default_cache  # noqa: E402

EFFECT_KIND = "bar_crown_track"


def _noise(rng, n, k, prefix):
    return {f"{prefix}{j:02d}": np.round(rng.standard_normal(n), 4) for j in range(k)}


def _per_run(df, values):
    """One value per run of ``df`` (in order of first appearance) spread to its samples."""
    runs = pd.unique(df["run"])
    return df["run"].map(dict(zip(runs, values))).to_numpy(float)


def _both(tr, te, fn):
    """Apply ``fn(df, which)`` -> dict of columns to TRAIN and TEST."""
    for df, which in ((tr, "train"), (te, "test")):
        for k, v in fn(df, which).items():
            df[k] = v


def _cut_runs(df, every, rng):
    parts = []
    for j, (_, g) in enumerate(df.groupby("run", sort=False)):
        parts.append(g.iloc[:int(rng.integers(3, 13))] if j % every == every - 1 else g)
    return pd.concat(parts)


def _session_counter(tr, te):
    t = np.concatenate([tr["time_s"].to_numpy(), te["time_s"].to_numpy()])
    rank = np.empty(len(t), dtype=np.int64)
    rank[np.argsort(t, kind="stable")] = np.arange(len(t))
    return rank[:len(tr)], rank[len(tr):]


def _rate_Hz(df):
    """The sample rate a logger computes from its own time stamps, 1 / (t[k] - t[k-1]) within each run (the first
    sample takes the second's): 1000 Hz up to the stamps' floating-point round-off."""
    dt = df.groupby("run", sort=False)["time_s"].diff().bfill().to_numpy(float)
    return 1.0 / dt


def _sparse(df, rng, every, level=45.0):
    v = np.round(level + 0.5 * rng.standard_normal(len(df)), 2)
    keep = np.zeros(len(df), bool)
    keep[::every] = True
    return np.where(keep, v, np.nan)


def variant(name: str, tr: pd.DataFrame, te: pd.DataFrame, rng) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The variant ``name`` of the frames (changed copies)."""
    tr, te = tr.copy(), te.copy()
    n = lambda df: len(df)  # noqa: E731
    if name in ("clean", "effect", "effect_renamed"):
        if name == "effect_renamed":
            tr, te = (d.rename(columns={"track_offset_mm": "track offset [mm]"}) for d in (tr, te))
    elif name in ("noise16", "effect_noise16"):
        _both(tr, te, lambda df, w: _noise(rng, n(df), 16, "aux_"))
    elif name == "noise8_run":
        _both(tr, te, lambda df, w: {f"setting_{j}": np.round(
            _per_run(df, rng.standard_normal(df["run"].nunique())) + 0.01 * rng.standard_normal(n(df)), 4)
            for j in range(8)})
    elif name == "int_run3":
        _both(tr, te, lambda df, w: {"fixture_id": _per_run(df, rng.integers(1, 4, df["run"].nunique())).astype(int)})
    elif name == "int_sample3":
        def status(df, w):
            out, v = np.empty(n(df), int), 0
            i = 0
            while i < n(df):
                k = int(rng.integers(20, 201))
                out[i:i + k] = v
                v = int(rng.integers(0, 3))
                i += k
            return {"daq_status": out}
        _both(tr, te, status)
    elif name == "limit_switch":
        _both(tr, te, lambda df, w: {"limit_switch": (df["position_m"].abs() > 0.021 - 0.0015).astype(int)})
    elif name == "const_train":
        _both(tr, te, lambda df, w: {"ambient_hPa": np.full(n(df), 1013.0 if w == "train" else 1009.5)})
    elif name == "const_all":
        _both(tr, te, lambda df, w: {"sample_rate_Hz": np.full(n(df), 1000)})
    elif name == "low_rate":
        t_all = np.sort(np.concatenate([tr["time_s"], te["time_s"]]))
        slot = np.floor(t_all / 0.05).astype(np.int64)
        levels = np.round(101.3 + np.cumsum(0.01 * rng.standard_normal(slot.max() + 1)), 3)
        _both(tr, te, lambda df, w: {"pressure_kPa": levels[np.floor(df["time_s"].to_numpy() / 0.05).astype(np.int64)]})
    elif name == "twins":
        def twins(df, w):
            v = np.round(_per_run(df, rng.standard_normal(df["run"].nunique())) + 0.05 * rng.standard_normal(n(df)), 4)
            return {"strain_a": v, "strain_b": v.copy()}
        _both(tr, te, twins)
    elif name == "affine_voltage":
        _both(tr, te, lambda df, w: {"amp_monitor_V": np.round(df["voltage_V"] / 100 + 0.05, 4)})
    elif name == "affine_load":
        _both(tr, te, lambda df, w: {"load_N": np.round(9.81 * df["load_kg"], 6)})
    elif name == "huge":
        _both(tr, te, lambda df, w: {"raw_counts": 1e9 * rng.standard_normal(n(df))})
    elif name == "tiny":
        _both(tr, te, lambda df, w: {"leak_A": 1e-9 * rng.standard_normal(n(df))})
    elif name == "offset_1e9":
        _both(tr, te, lambda df, w: {"gauge_raw": np.round(1e9 + rng.standard_normal(n(df)), 3)})
    elif name == "epoch_clock":
        _both(tr, te, lambda df, w: {"pc_time_s": np.round(1764669600.0 + df["time_s"], 3)})
    elif name == "counter":
        a, b = _session_counter(tr, te)
        tr["sample_counter"], te["sample_counter"] = a, b
    elif name == "outlier_run":
        _both(tr, te, lambda df, w: {"vibration_g": np.round(0.01 * rng.standard_normal(n(df)), 5)})
        r = pd.unique(tr["run"])[len(pd.unique(tr["run"])) // 2]
        sel = tr["run"] == r
        tr.loc[sel, "vibration_g"] = np.round(50 + 0.01 * rng.standard_normal(int(sel.sum())), 5)
    elif name == "nan_sparse":
        tr["humidity_pct"] = _sparse(tr, rng, 100)
        te["humidity_pct"] = _sparse(te, rng, 100)
        first_te = te["run"] == pd.unique(te["run"])[0]
        te.loc[first_te, "humidity_pct"] = np.nan
        tr.loc[tr.index[250], "humidity_pct"] = np.inf
    elif name == "nan_test":
        tr["humidity_pct"] = _sparse(tr, rng, 1)
        te["humidity_pct"] = _sparse(te, rng, 25)
    elif name == "speed_copy":
        _both(tr, te, lambda df, w: {"laser_speed_m_s": np.round(df["speed_m_s"] + 1e-3 * rng.standard_normal(n(df)), 6)})
    elif name == "position_copy":
        _both(tr, te, lambda df, w: {"laser_position_mm": np.round(1000 * df["position_m"] + 1e-3 * rng.standard_normal(n(df)), 4)})
    elif name == "odd_names":
        _both(tr, te, lambda df, w: {k: np.round(rng.standard_normal(n(df)), 4)
                                     for k in ("Ch 3 (V)", "T[degC]", "x*y", "µstrain")})
    elif name == "short_runs":
        tr, te = _cut_runs(tr, 5, rng), _cut_runs(te, 4, rng)
    elif name == "two_voltages":
        tr = tr[tr["voltage_V"].isin((220.0, 324.0))]
    elif name == "quasi_const":
        _both(tr, te, lambda df, w: {"rate_Hz": _rate_Hz(df)})
    elif name == "test_only":
        te["probe_mV"] = np.round(rng.standard_normal(n(te)), 4)
    elif name == "affine_direction":
        _both(tr, te, lambda df, w: {"relay_ch1": (df["direction"] > 0).astype(int)})
    elif name == "nan_test_all":
        tr["humidity_pct"] = _sparse(tr, rng, 1)
        te["humidity_pct"] = np.nan
    elif name == "effect_twins":
        _both(tr, te, lambda df, w: {"track_offset_copy_mm": df["track_offset_mm"].copy()})
    elif name in ("effect_scaled", "effect_tiny"):
        f, new = (1e9, "track_offset_pm_e3") if name == "effect_scaled" else (1e-9, "track_offset_Mm_e3")
        tr, te = (d.rename(columns={"track_offset_mm": new}) for d in (tr, te))
        for d in (tr, te):
            d[new] = d[new] * f
    elif name == "effect_sparse":
        for d in (tr, te):
            keep = np.zeros(len(d), bool)
            keep[::10] = True
            d["track_offset_mm"] = d["track_offset_mm"].where(keep)
    elif name == "noise40":
        _both(tr, te, lambda df, w: _noise(rng, n(df), 40, "aux_"))
    elif name == "one_direction":
        tr, te = tr[tr["direction"] > 0], te[te["direction"] > 0]
    elif name == "single_load":
        tr = tr[tr["load_kg"] == 0.0]
    elif name == "single_voltage":
        tr = tr[tr["voltage_V"] == 324.0]
    elif name == "test_one_run":
        te = te[te["run"] == pd.unique(te["run"])[0]]
    elif name == "long_pause":
        starts = np.sort(np.concatenate([d.groupby("run", sort=False)["time_s"].min() for d in (tr, te)]))
        t_mid = starts[len(starts) // 2]                       # a run's first stamp: the gap falls before it
        for d in (tr, te):
            d["time_s"] = np.round(d["time_s"] + np.where(d["time_s"] >= t_mid, 86400.0, 0.0), 3)
    else:
        raise SystemExit(f"unknown variant {name}")
    return tr, te


VARIANTS = ("clean", "noise16", "noise8_run", "int_run3", "int_sample3", "limit_switch", "const_train", "const_all",
            "low_rate", "twins", "affine_voltage", "affine_load", "huge", "tiny", "offset_1e9", "epoch_clock",
            "counter", "outlier_run", "nan_sparse", "nan_test", "speed_copy", "position_copy", "odd_names",
            "short_runs", "two_voltages", "effect", "effect_noise16", "effect_renamed",
            # a second batch (appended: the earlier variants keep their random streams)
            "quasi_const", "test_only", "affine_direction", "nan_test_all", "effect_twins", "effect_scaled",
            "effect_tiny", "effect_sparse",
            # a third batch: plans and clocks
            "noise40", "one_direction", "single_load", "single_voltage", "test_one_run", "long_pause")


def _non_finite(obj) -> list:
    """Paths of NaN (null in a metric) or infinity tokens in the report's metrics."""
    bad = []

    def walk(o, path):
        if isinstance(o, dict):
            for k, v in o.items():
                walk(v, f"{path}.{k}")
        elif isinstance(o, list):
            for j, v in enumerate(o):
                walk(v, f"{path}[{j}]")
        elif o == "inf" or o == "-inf" or (isinstance(o, float) and not np.isfinite(o)):
            bad.append(path)
    walk(obj, "")
    return bad


def run_variant(name: str, seed: int, cache: Path, work: Path) -> dict:
    src = data_dir(EFFECT_KIND if name.startswith("effect") else "clean", seed, cache,
                   _effect_maker() if name.startswith("effect") else None)
    d = work / name
    shutil.rmtree(d, ignore_errors=True)
    d.mkdir(parents=True)
    rng = np.random.default_rng([seed, 130, VARIANTS.index(name)])
    tr, te = variant(name, pd.read_csv(src / "train.csv"), pd.read_csv(src / "test.csv"), rng)
    for part, df in (("train", tr), ("test", te)):
        df.to_csv(d / f"{part}.csv", index=False)
        shutil.copy(src / f"{part}.json", d / f"{part}.json")
    cmd = [sys.executable, "-m", "l1b2.cli", "close-loop", "--train", str(d / "train.csv"), "--test",
           str(d / "test.csv"), "--out", str(d / "out"), "--no-plots", "--quiet", "--workers", "0"]
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, OPENBLAS_NUM_THREADS="1"))
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    (d / "stdout.txt").write_text(p.stdout)
    (d / "stderr.txt").write_text(p.stderr)
    err = [ln for ln in p.stderr.splitlines() if ln.strip()]
    row = {"variant": name, "seed": seed, "rc": p.returncode, "stderr_last": err[-1] if err else "",
           "traceback": "Traceback" in p.stderr}
    rep = d / "out" / "report.json"
    if p.returncode == 0 and rep.exists():
        r = json.loads(rep.read_text())
        diag = r["diagnosis"]
        b = r["baseline"]["test"]["free_run"]["nrmse"]
        a = (r["extended"] or r["baseline"])["test"]["free_run"]["nrmse"]
        aux = [{k: c.get(k) for k in ("channel", "action", "note")} for c in diag.get("auxiliary_columns") or []]
        md = (d / "out" / "report.md").read_text()
        row |= {"traced_all": diag["traced_to"], "added": [e["label"] for e in diag["effects"]],
                "before": None if b is None else round(100 * b, 3), "after": None if a is None else round(100 * a, 3),
                "non_finite": _non_finite({"baseline": r["baseline"], "extended": r["extended"],
                                           "rounds": r["rounds"]}),
                "nan_in_md": any(tok in md.lower().split() for tok in ("nan", "nan%", "inf", "inf%")),
                "channels": [c.get("channel") for c in diag.get("channels_considered") or []],
                "auxiliary_columns": aux, "message": diag["message"]}
    row["cpu_s"] = round(cpu, 1)
    return row


def _effect_maker():
    import blind_effects_tenth
    return blind_effects_tenth.experiment


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("variants", nargs="*", help="variants to run (default: all): " + ", ".join(VARIANTS))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cache", default=default_cache())
    ap.add_argument("--work", default=str(Path(os.environ.get("TMPDIR", "/tmp")) / "l1b2_valid_oddities"))
    ap.add_argument("--rows", default="", help="append each row to this JSON-lines file")
    args = ap.parse_args(argv)
    unknown = [v for v in args.variants if v not in VARIANTS]
    if unknown:
        ap.error(f"unknown variant(s): {unknown}")
    for name in args.variants or VARIANTS:
        row = run_variant(name, args.seed, Path(args.cache), Path(args.work))
        line = json.dumps(row, ensure_ascii=False)
        print(line, flush=True)
        if args.rows:
            with open(args.rows, "a") as fh:
                fh.write(line + "\n")


if __name__ == "__main__":
    main()
