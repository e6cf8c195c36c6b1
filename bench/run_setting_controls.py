"""Controls of the run settings (decision 0180): two decoys whose readings carry a level per run that acts on nothing.

The loop derives a run setting from a column the motion makes in part (a response of the speed, a reading along the
stroke) when the plan does not fix its run levels and they scatter beyond their noise (``l1b2.closeloop.runsetting``).
These controls make such a column from the clean case's data (``bench/blind_effects.py clean SEED``, the same runs,
the motor untouched), so the setting is derived and offered, and must not be traced:

* ``tacho_offset_decoy`` -- logged ``tacho_V``: a tachogenerator on the carriage's pulley, ``K v + z_r`` with ``K``
  0.4 V s/m, its amplifier's zero ``z_r`` re-trimmed before each run (uniform in -50..+50 mV), 1 mV of noise, 0.1 mV
  resolution (``v`` the logged speed). A response of the speed (its echo, signed), its level the run's trim.
* ``cell_zero_decoy`` -- logged ``side_cell_N``: a load cell on a side spring that the carriage deflects along the
  stroke, ``0.8 (s / 0.021 m)^2`` N, its bridge re-zeroed before each run with an error ``z_r`` (uniform in -0.3..+0.3
  N), 5 mN of noise, 1 mN resolution (``s`` the logged position). Read along the stroke, its level the run's zero.

Each draws ``z_r`` for the 72 runs of the protocol from ``np.random.default_rng([seed, 180, KINDS.index(kind)])``
(run ``r`` takes entry ``r - 1``) and its noise from ``[seed, 181, KINDS.index(kind), first run of the file]``. Pass
rule (the decoys' of the audits): the column's stem (``DECOY``) nowhere in the traced regressors and ``a <= 1.02 b``
(TEST free-run nrmse after and before the loop).

Usage: python bench/run_setting_controls.py KIND SEED [--cache DIR] [--report FILE]. Prints one JSON line as
``bench/blind_effects.py`` does, plus ``traced_all`` and ``passes``.
"""
import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

KINDS = ("tacho_offset_decoy", "cell_zero_decoy")
#: each decoy's column and the stem that must not be traced
CHANNEL = {"tacho_offset_decoy": "tacho_V", "cell_zero_decoy": "side_cell_N"}
DECOY = {"tacho_offset_decoy": "tacho", "cell_zero_decoy": "side_cell"}
N_RUNS = 72
TACHO_K_V_S_M = 0.4
TACHO_ZERO_V = 0.05
TACHO_NOISE_V = 1e-3
CELL_N = 0.8
CELL_HALF_STROKE_M = 0.021
CELL_ZERO_N = 0.3
CELL_NOISE_N = 5e-3


def zeros(kind: str, seed: int) -> np.ndarray:
    """The runs' zero errors ``z_r`` [V or N], entry ``r - 1`` for run ``r``."""
    top = TACHO_ZERO_V if kind == "tacho_offset_decoy" else CELL_ZERO_N
    return np.random.default_rng([seed, 180, KINDS.index(kind)]).uniform(-top, top, N_RUNS)


def reading(kind: str, seed: int, df: pd.DataFrame) -> np.ndarray:
    """The decoy's logged column on the samples of ``df`` (module docstring)."""
    z = zeros(kind, seed)[df["run"].to_numpy(int) - 1]
    noise = np.random.default_rng([seed, 181, KINDS.index(kind), int(df["run"].iloc[0])]).standard_normal(len(df))
    if kind == "tacho_offset_decoy":
        return np.round((TACHO_K_V_S_M * df["speed_m_s"].to_numpy(float) + z + TACHO_NOISE_V * noise) * 1e4) / 1e4
    s = df["position_m"].to_numpy(float) / CELL_HALF_STROKE_M
    return np.round((CELL_N * s * s + z + CELL_NOISE_N * noise) * 1e3) / 1e3


def make(kind: str, seed: int, cache: Path) -> Path:
    """The decoy's TRAIN and TEST in ``cache/<kind>_<seed>``: the clean case's files with the column added."""
    src = be.data_dir("clean", seed, cache, None)
    dst = cache / f"{kind}_{seed}"
    dst.mkdir(parents=True, exist_ok=True)
    for part in ("train", "test"):
        df = pd.read_csv(src / f"{part}.csv")
        df[CHANNEL[kind]] = reading(kind, seed, df)
        df.to_csv(dst / f"{part}.csv", index=False)
        shutil.copy(src / f"{part}.json", dst / f"{part}.json")
    return dst


def passes(row: dict) -> bool:
    """The decoy's pass rule on a printed row (the audits' rule for a decoy, :func:`blind_effects.audit_verdict`)."""
    return be.audit_verdict(row, {}, DECOY, None)["passes"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("kind", choices=KINDS)
    ap.add_argument("seed", type=int)
    ap.add_argument("--cache", default=be.default_cache())
    be.report_option(ap)
    args = ap.parse_args(argv)
    d = make(args.kind, args.seed, Path(args.cache))
    row, res = be.loop_row(args.kind, args.seed, d, traced_all=lambda names, diag: list(diag["traced_to"]))
    row["passes"] = passes(row)
    print(json.dumps(row))
    be.write_report(args.report, res)


if __name__ == "__main__":
    main()
