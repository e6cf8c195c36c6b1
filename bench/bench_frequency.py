#!/usr/bin/env python
"""Benchmark: the drive-frequency response's estimation, former profile likelihood vs joint least squares.

The data: the realistic motor's rig (1 mm/s speed noise, 2 % run scatter, the paper's 72-run plan, TEST =
|load| 0.05 kg) at 48.0, 48.25, 48.5, 48.75 and 49.0 kHz with a +-50 Hz per-run offset (TRAIN spans
47.95-49.05 kHz, +-550 Hz around the drive), and the same plan at 48.5 kHz only; made once per seed and
cached (``--cache``).

Prints, side by side in one run (same data, same process), for each seed and model family: the held-out
free-run nrmse of the single-frequency identification, of the multi-frequency identification with the
former profile-likelihood estimation (``fit_frequency_response_profile``) and with the joint estimation
(``fit_frequency_response``, the default), their ratios to the single-frequency figure (target <= 1.2) and
the CPU time of each identification (``time.process_time``); for the pure-slip family also the ratio to
Eq. 29's single-frequency figure of the seed, and any response parameter that ended at its bound. With
``--diagnose`` also where the joint fit's held-out error lies: the free-run rms error and its mean signed
error (drive direction positive; both in % of TEST's rms speed, on the samples the nrmse evaluates) per
drive-frequency level (runs rounded to 250 Hz), V0 and load, and the fitted model's steady speed (s = 0, no
load) against the coupled physics' (:func:`l1b2.physics.steady.steady_state`, the realistic world's truth)
over frequency at 220 and 324 V. With ``--contact`` the pure-slip family's multi-frequency identification
also runs with the contact law (``fit_frequency_response(contact=True)``, the setting ``frequency="contact"``,
decision 0038) on the same data in the same process, printed after the existing form's line: its held-out
nrmse, ratio to the single-frequency figure, CPU time, the estimates and whether the law was kept. With
``--contact-from-0029`` (a shorter run) the existing form is the identification at decision 0029's joint B2
estimate of the seed held fixed (:data:`B2_0029`; the joint estimation's own last step, without its grid) and
the contact stage starts from that fit (``fit_frequency_response(contact=True, b2=...)``); its CPU time is
then the contact stage's alone.

Usage: python bench/bench_frequency.py [--seeds 1,2,3] [--models eq29,pure_slip] [--joint-models pure_slip]
       [--skip-profile] [--diagnose] [--contact] [--cache DIR]
"""
import argparse
import dataclasses
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.data.measurements import load_measurements  # noqa: E402
from l1b2.data.metrics import evaluation_mask, report_metrics  # noqa: E402
from l1b2.ident.estimator import PredictorIdentifier  # noqa: E402
from l1b2.ident.frequency import (fit_frequency_response, fit_frequency_response_profile,  # noqa: E402
                                  reference_frequency)
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402
from l1b2.physics.steady import steady_state  # noqa: E402
from l1b2.predictor.frequency import FrequencyResponse, contact_angle  # noqa: E402
from l1b2.predictor.model import steady_state as model_steady_state  # noqa: E402
from l1b2.rig.experiment import RigPlan, run_experiment, write_experiment  # noqa: E402

FREQS = (48000.0, 48250.0, 48500.0, 48750.0, 49000.0)
#: the pure-slip family's joint B2 estimates of decision 0029 on these data (seeds 1-3): f_b0 [Hz], zeta_b
B2_0029 = {1: (46303.0, 0.0149), 2: (46215.0, 0.0135), 3: (46456.0, 0.0170)}
TARGET_RATIO = 1.2


def rig_data(cache: Path, seed: int, multi: bool) -> Path:
    out = cache / f"{'multi' if multi else 'single'}_{seed}"
    if not (out / "test.csv").exists():
        plan = RigPlan(step_s=1e-3, seed=seed, speed_noise_m_s=1e-3, run_scatter=0.02)
        if multi:
            plan = dataclasses.replace(plan, frequencies_Hz=FREQS, frequency_jitter_Hz=50.0)
        mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
        df, truth = run_experiment(plan, mp, engine="inprocess", workers=1)
        write_experiment(df, out, mp, plan, truth)
    return out


def held_out(est, te) -> float:
    return 100 * report_metrics(te.df, est.predict_one_step(te), est.predict_free_run(te))["free_run"]["nrmse"]


def diagnose(est, te) -> None:
    """Print where the held-out free-run error lies (module docstring, ``--diagnose``)."""
    keep = evaluation_mask(te.df)                       # the samples the held-out nrmse evaluates
    df = te.df[keep]
    v = df["speed_m_s"].to_numpy()
    e = est.predict_free_run(te)[keep] - v
    scale = math.sqrt(float((v ** 2).mean()))
    axes = (("f [Hz]", (df["frequency_Hz"].to_numpy() / 250).round() * 250), ("V0 [V]", df["voltage_V"].to_numpy()),
            ("load [kg]", df["load_kg"].to_numpy()))
    for name, key in axes:
        cells = []
        for k in sorted(set(key)):
            sel = key == k
            rms = 100 * math.sqrt(float((e[sel] ** 2).mean())) / scale
            bias = 100 * float((e[sel] * df["direction"].to_numpy()[sel]).mean()) / scale
            cells.append(f"{k:g}: {rms:.2f} ({bias:+.2f})")
        print(f"       {name:>9} rms (bias) %: " + "  ".join(cells))
    resp = FrequencyResponse.from_dict((est.result_.frequency or {}).get("response"))
    mp = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    for V0 in (220.0, 324.0):
        cells = []
        for f in (47950.0, 48250.0, 48500.0, 48750.0, 49050.0):
            truth = steady_state(mp, 0.0, V0, 0.0, 1, f_Hz=f).v_m_s
            a = None if resp is None or not resp.has_contact else contact_angle(V0, f, resp)
            model = float(model_steady_state(est.params_, 0.0, V0 * (1.0 if resp is None else float(resp.gain(f))),
                                             0.0, 1, est.m_s_, contact=a))
            cells.append(f"{f / 1e3:.2f} kHz {1e3 * truth:.1f}/{1e3 * model:.1f} ({100 * (model / truth - 1):+.1f} %)")
        print(f"       steady speed physics/model mm/s, {V0:.0f} V: " + "  ".join(cells))


def fixed_b2(est, tr, seed):
    """Identify with decision 0029's joint B2 estimate of ``seed`` held fixed."""
    est.frequency = FrequencyResponse(reference_frequency(tr), *B2_0029[seed])
    return est.fit(tr)


def identify(folder: Path, model: str, how=None, show=False):
    tr, te = load_measurements(folder / "train.csv"), load_measurements(folder / "test.csv")
    est = PredictorIdentifier(order=8, fixed="recommended", n_starts=4, seed=0, model=model)
    c0 = time.process_time()
    if how is None:
        est.fit(tr)
    else:
        how(est, tr)
    cpu = time.process_time() - c0
    if show:
        diagnose(est, te)
    return held_out(est, te), cpu, (est.result_.frequency or {}), est


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--models", default="eq29,pure_slip")
    ap.add_argument("--joint-models", default=None,
                    help="families whose multi-frequency identification runs (default: all of --models; the others "
                         "give their single-frequency figure only)")
    ap.add_argument("--skip-profile", action="store_true", help="leave out the former (slow) estimation")
    ap.add_argument("--diagnose", action="store_true", help="where the joint fit's held-out error lies (docstring)")
    ap.add_argument("--contact", action="store_true",
                    help="pure slip: also the multi-frequency identification with the contact law (docstring)")
    ap.add_argument("--contact-from-0029", action="store_true",
                    help="pure slip: the existing form at decision 0029's joint estimate held fixed, and the contact "
                         "stage from it (docstring)")
    ap.add_argument("--cache", default=str(Path(os.environ.get("TMPDIR", "/tmp")) / "l1b2_bench_frequency"))
    a = ap.parse_args()
    cache = Path(a.cache)
    print(f"{'seed':>4} {'model':>9} | {'single %':>8} {'cpu s':>6} | {'profile %':>9} {'ratio':>5} {'cpu s':>6} | "
          f"{'joint %':>7} {'ratio':>5} {'cpu s':>6} | {'/eq29':>5} | joint f_b0 [Hz], zeta_b")
    for seed in (int(s) for s in a.seeds.split(",")):
        single, multi = rig_data(cache, seed, False), rig_data(cache, seed, True)
        models = a.models.split(",")
        singles = {m: identify(single, m)[:2] for m in sorted(models, key=lambda m: m != "eq29")}
        eq29_single = singles.get("eq29", (float("nan"),))[0]
        for model in models if a.joint_models is None else a.joint_models.split(","):
            e1, c1 = singles[model]
            if a.skip_profile:
                ep, cp = float("nan"), float("nan")
            else:
                ep, cp, _, _ = identify(multi, model, fit_frequency_response_profile)
            b2_given = a.contact_from_0029 and model == "pure_slip"
            if b2_given:      # the existing form at decision 0029's joint estimate, held fixed (one identification)
                ej, cj, rec, b2 = identify(multi, model, lambda est, tr: fixed_b2(est, tr, seed), show=a.diagnose)
            else:
                ej, cj, rec, b2 = identify(multi, model, fit_frequency_response, show=a.diagnose)
            r = rec.get("response") or {}
            bound = f" AT BOUND: {'; '.join(rec['at_bound'])}" if rec.get("at_bound") else ""
            print(f"{seed:>4} {model:>9} | {e1:8.2f} {c1:6.1f} | {ep:9.2f} {ep / e1:5.2f} {cp:6.1f} | "
                  f"{ej:7.2f} {ej / e1:5.2f} {cj:6.1f} | {ej / eq29_single:5.2f} | "
                  f"{r.get('f_b0_Hz', float('nan')):.0f}, {r.get('zeta_b', float('nan')):.4f}{bound}", flush=True)
            if a.contact and model == "pure_slip":
                ec, cc, rec, _ = identify(multi, model, lambda est, tr: fit_frequency_response(
                    est, tr, contact=True, b2=b2 if b2_given else None), show=a.diagnose)
                r, kept = rec.get("response") or {}, rec.get("contact") or {}
                bound = f" AT BOUND: {'; '.join(rec['at_bound'])}" if rec.get("at_bound") else ""
                print(f"{seed:>4} {'+contact':>9} | {e1:8.2f} {c1:6.1f} | {'':>9} {'':>5} {'':>6} | "
                      f"{ec:7.2f} {ec / e1:5.2f} {cc:6.1f} | {ec / eq29_single:5.2f} | "
                      f"{r.get('f_b0_Hz', float('nan')):.0f}, {r.get('zeta_b', float('nan')):.4f}; f_l0 "
                      f"{r.get('f_l0_Hz', float('nan')):.0f} Hz, contact_V {r.get('contact_V', float('nan')):.1f} V; "
                      f"kept {kept.get('kept')} (loglik B2 {kept.get('b2_loglik', float('nan')):.1f}, contact "
                      f"{kept.get('contact_loglik') or float('nan'):.1f}){bound}", flush=True)
    print(f"target: joint ratio <= {TARGET_RATIO} on every seed (ratio: to the same family's single-frequency figure; "
          "/eq29: to Eq. 29's single-frequency figure of the seed)")


if __name__ == "__main__":
    main()
