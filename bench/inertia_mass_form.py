#!/usr/bin/env python
"""A logged channel's inertia form, first order against the mass inside the free run, on a blind case.

``python bench/inertia_mass_form.py AUDIT KIND SEED CHANNEL`` (AUDIT: ``base``, ``more``, ``third``, ``fourth``,
the blind audit script that makes the case). The close loop's baseline on TRAIN (its round 0:
``close_loop(..., max_rounds=0)``) is held fixed; on TRAIN's evaluation mask each form of the channel's run mean
(linear shape with its constant: ``a z + a_0``) is fitted by least squares of the free run:

* ``first_order``: the loop's inertia form, the force ``-m_s d a_base (a z + a_0)`` added to the drive force
  (``a_base`` the baseline's free-run acceleration, :func:`l1b2.predictor.effects.time_derivative`);
* ``first_order_weight``: the same plus the heavier slider's weight on the guide, ``mu_sd 9.81 m_s (a z + a_0)
  sign(-v')`` at the baseline's speed (the exact form's linearisation);
* ``mass``: the slider's mass ``m_s (1 + a z + a_0)`` inside the recursion
  (:func:`l1b2.predictor.simulate.mass_sensitivity`, its exact Jacobian), bounded to a positive mass;
* ``friction``, ``force_factor``: the channel's force forms with a constant, ``-(a z + a_0)`` and
  ``V0/V_ref (a z + a_0)`` [N], for comparison;
* ``known`` (``payload_g`` only): the slider's mass plus each run's known payload, nothing fitted.

Prints one JSON line: TEST's free-run nrmse [%] (:func:`l1b2.data.metrics.report_metrics`) of the baseline and
of each fit, the fitted parameters, the mass form's floor over TRAIN's range [kg] and the CPU time [s].
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.closeloop.loop import close_loop  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.data.metrics import report_metrics  # noqa: E402
from l1b2.predictor import effects as fx  # noqa: E402
from l1b2.predictor import simulate as sim  # noqa: E402
from l1b2.predictor.effects import channels as ch  # noqa: E402

AUDITS = {"base": "blind_effects", "more": "blind_effects_more", "third": "blind_effects_third",
          "fourth": "blind_effects_fourth"}


def inputs(df):
    """The free run's inputs of a frame: s, V0, load, d, t, the measured speed, run ids."""
    col = lambda c: df[c].to_numpy(float)  # noqa: E731
    return (col(dataio.POSITION), col(dataio.VOLTAGE), col(dataio.LOAD), col(dataio.DIRECTION), col(dataio.TIME),
            col(dataio.SPEED), df[dataio.RUN].to_numpy())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("audit", choices=tuple(AUDITS))
    ap.add_argument("kind")
    ap.add_argument("seed", type=int)
    ap.add_argument("channel")
    args = ap.parse_args(argv)
    mod = importlib.import_module(AUDITS[args.audit])
    d = be.data_dir(args.kind, args.seed, Path(be.default_cache()), None if args.kind == "clean" else mod.experiment)
    train, test = dataio.load_measurements(d / "train.csv"), dataio.load_measurements(d / "test.csv")
    c0 = time.process_time()
    res = close_loop(train, test, max_rounds=0)
    base, m_s = res.baseline_model, float(train.slider_mass_kg)
    p = base.params_
    dtr, dte = res.train_df, res.test_df
    mask_tr = np.asarray(train.mask, bool)
    row = {"kind": args.kind, "seed": args.seed, "channel": args.channel, "family": p.drive_law}
    fr = {k: inputs(f) for k, f in (("train", dtr), ("test", dte))}
    v_start = {k: f[5] for k, f in fr.items()}

    def run(k, m=m_s, force=None):
        s, V0, load, dd, t, _, r = fr[k]
        return sim.free_run(p, s, V0, load, dd, t, v_start[k], m, run_index=r, extra_force=force)

    check = float(np.max(np.abs(run("train") - base.predict_free_run(dtr))))
    row["baseline_equal_m_s"] = check
    nrmse = lambda v: round(100 * report_metrics(dte, base.predict_one_step(dte), v)["free_run"]["nrmse"], 3)  # noqa
    row["test_baseline"] = nrmse(run("test"))
    if p.drive_law != "eq29" or check > 1e-9:
        row["skipped"] = "the baseline is not Eq. 29's free run of its parameters"
        print(json.dumps(row))
        return
    c_tr = dtr.groupby(dataio.RUN, sort=False)[args.channel].transform("mean").to_numpy(float)
    spec = {"kind": "channel", "channel": args.channel, "form": "inertia", "level": "run", "m_s": m_s,
            "mean": float(np.mean(dtr[args.channel])), "sd": float(np.std(dtr[args.channel])), "run_spread": 0.0}
    xs, ab = {}, {}
    for k, f in (("train", dtr), ("test", dte)):
        xs[k] = {"run:" + args.channel: f.groupby(dataio.RUN, sort=False)[args.channel].transform("mean")
                 .to_numpy(float), "d": fr[k][3]}
        starts = [sl.start for _, sl in dataio.run_slices(f[dataio.RUN])]
        ab[k] = np.asarray(fx.time_derivative(run(k), fr[k][4], sorted(starts)), float)
    y = fr["train"][5][mask_tr]

    def first_force(k, phi):
        return (-m_s * fr[k][3] * ab[k])[:, None] * ch.mass_columns(spec, xs[k]) @ phi

    fo = least_squares(lambda phi: run("train", force=first_force("train", phi))[mask_tr] - y, np.zeros(2))
    row["test_first_order"] = nrmse(run("test", force=first_force("test", fo.x)))
    row["first_order_phi"] = [round(float(v), 4) for v in fo.x]
    vb = {k: run(k) for k in fr}

    def weight_force(k, phi):   # the first order plus the heavier slider's weight on the guide, mu_sd g dm sign(-v')
        return first_force(k, phi) + (p.mu_sd * 9.81 * m_s * np.sign(-fr[k][3] * vb[k]))[:, None] * ch.mass_columns(
            spec, xs[k]) @ phi

    fw = least_squares(lambda phi: run("train", force=weight_force("train", phi))[mask_tr] - y, np.zeros(2))
    row["test_first_order_weight"] = nrmse(run("test", force=weight_force("test", fw.x)))
    row["first_order_weight_phi"] = [round(float(v), 4) for v in fw.x]
    row["mu_sd"] = round(float(p.mu_sd), 4)
    for form, fac in (("friction", lambda k: -np.ones(len(fr[k][0]))), ("force_factor", lambda k: fr[k][1] / fx.V_REF)):
        cols = lambda k: fac(k)[:, None] * ch.mass_columns(spec, xs[k])  # noqa: E731  (the form's [z, 1] columns)
        ff = least_squares(lambda phi: run("train", force=cols("train") @ phi)[mask_tr] - y, np.zeros(2))
        row[f"test_{form}"] = nrmse(run("test", force=cols("test") @ ff.x))
        row[f"train_sse_{form}"] = round(float(2 * ff.cost), 4)
    s, V0, load, dd, t, _, r = fr["train"]
    M = m_s * ch.mass_columns(spec, xs["train"])

    def resid(phi):
        return run("train", ch.slider_mass(spec, xs["train"], phi))[mask_tr] - y

    def jac(phi):
        return sim.mass_sensitivity(p, s, V0, load, dd, t, v_start["train"], ch.slider_mass(spec, xs["train"], phi),
                                    M, run_index=r)[1][mask_tr]

    ms = least_squares(resid, np.zeros(2), jac=jac, bounds=([-10.0, -0.95], [10.0, 20.0]))
    row["test_mass"] = nrmse(run("test", ch.slider_mass(spec, xs["test"], ms.x)))
    row["mass_phi"] = [round(float(v), 4) for v in ms.x]
    row["mass_floor_kg"] = round(ch.mass_floor(spec, ms.x, float(np.min(c_tr)), float(np.max(c_tr))), 4)
    row["train_sse_first_order_weight_mass"] = [round(float(2 * c), 4) for c in (fo.cost, fw.cost, ms.cost)]
    if args.channel == "payload_g":
        row["test_known"] = nrmse(run("test", m_s + xs["test"]["run:payload_g"] / 1000.0))
        row["known_phi"] = [round(spec["sd"] / 1000.0 / m_s, 4), round(spec["mean"] / 1000.0 / m_s, 4)]
    row["cpu_s"] = round(time.process_time() - c0, 1)
    print(json.dumps(row))


if __name__ == "__main__":
    main()
