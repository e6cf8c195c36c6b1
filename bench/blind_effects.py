#!/usr/bin/env python
"""A blind audit of the close loop: effects of kinds that no injection of the rig and no candidate of the loop names.

Every kind here lives in this script only (nothing in the package knows it) and acts through the co-simulation of
the realistic world (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s speed
noise and a 2 % run-to-run contact scatter, as ``tests/test_closeloop_realistic.py`` makes its data): it sets FMU
parameters or inputs per run or per sample, never the recorded speed. The kinds, their physics and the channel the
data carries them in:

* ``humidity_friction`` -- logged auxiliary column ``humidity_pct`` (one value per run plus sensor noise, a column no
  code of the package names). Adsorbed water lubricates the ceramic tip on the lining: the Coulomb slip friction
  coefficient is ``mu_p (1 - A tanh((RH - 45 %) / 8 %))``, saturating once the film is formed. RH per run
  ``45 + 15 z`` (z standard normal, clipped to 20-80 %), A drawn in 0.08-0.12.
* ``chamber_temperature`` -- logged ``temperature_C``, constant within a run and different between runs (a thermal
  chamber at a new set point per condition, 18-34 degC uniform). The stator's B2 resonance moves with its
  temperature (``Stator.df_dT_b_Hz_per_K`` drawn in -30..-20 Hz/K; L1 does not move); the operator set the supply
  at 25 degC, so the drive's tank also drifts (its inductor's temperature coefficient, part of the world).
* ``lining_wear`` -- no channel. The lining wears by Archard's law: wear grows with the tip's sliding distance,
  ``S_k`` summed over the runs before run k (tip speed ~ 0.2 m/s x V0/324 V times the run's duration), and the
  friction coefficient glazes, ``mu_p (1 - W (1 - exp(-S/S0)))`` (W 0.10-0.16, S0 1.5-3 m; a session slides ~4 m).
* ``vco_warmup`` -- logged ``frequency_Hz`` per sample. The drive's oscillator starts each run off its set point and
  settles, ``f(t) = f0 + D exp(-t/tau)`` (D drawn per run in +150..+400 Hz, tau 0.08-0.15 s for the session), t from
  the run's start; the operator's supply setting is for f0.
* ``humidity_capillary`` -- the same logged ``humidity_pct``, a non-monotone law: water menisci at the contact's
  asperities add an adhesive normal force that is largest at intermediate humidity and vanishes when the film
  floods them, ``mu_p (1 + B (exp(-((RH - 50 %) / 12 %)^2) - 1/2))`` (B 0.15-0.20; RH as above). A probe of the
  channel forms' shape: its run-level correlation with RH itself is weak.
* ``cable_preload`` -- the load's own column, acting through the preload: the pulley's cable leaves the slider at an
  angle (drawn 15-25 deg) toward the bar, so the load's weight adds ``|m| g sin(angle)`` to the preload (the
  cable pulls the slider onto the bar whichever way the load hangs).
* ``humidity_pulley`` -- the same logged ``humidity_pct`` acting through the load's path (a channel x load
  interaction): the pulley runs in a hygroscopic polymer bushing whose Coulomb friction follows its water uptake, a
  BET sorption isotherm ``u(a) = C a / ((1 - a)(1 - a + C a))`` of the relative humidity ``a = RH/100``
  (``C`` drawn in 8-15), ``pulley_mu = M u(a) / u(0.45)`` (M drawn in 0.25-0.35, the rig's range of a pulley's
  friction): a friction ``pulley_mu g |m|`` that grows with the load and, convexly, with the humidity (nothing at
  no load). RH as above.

Usage: python bench/blind_effects.py KIND SEED [--cache DIR]       (KIND: one of the above or clean)
Prints one JSON line: traced (first two), added, TEST free-run nrmse before and after, the channels considered,
whether the effect's channel was among them, and the CPU time of the close loop (``time.process_time``).
"""
import argparse
import functools
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fmu_src"))

from l1b2.closeloop.loop import close_loop  # noqa: E402
from l1b2.cosim.engine import InProcessMotor  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.data.measurements import load_measurements  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.params import SYSTEM_MODELS_DIR, load_motor  # noqa: E402
from l1b2.rig.experiment import (RigPlan, add_speed_noise, plan_runs, run_contact_factors,  # noqa: E402
                                 sampling_every, scattered_motor, write_experiment)

KINDS = ("humidity_friction", "chamber_temperature", "lining_wear", "vco_warmup", "cable_preload",
         "humidity_capillary", "humidity_pulley")
#: the channel each kind acts through (as the loop's report names channels), None: none logged
CHANNEL = {"humidity_friction": "humidity_pct", "chamber_temperature": "temperature_C", "lining_wear": None,
           "vco_warmup": "frequency_Hz", "cable_preload": "load_kg", "humidity_capillary": "humidity_pct",
           "humidity_pulley": "humidity_pct"}
#: the regressor the loop should trace (its report's name of the channel; the session clock for the unlogged wear)
WANT = {"humidity_friction": "humidity_pct", "chamber_temperature": "temperature", "lining_wear": "time",
        "vco_warmup": "frequency", "cable_preload": "load", "humidity_capillary": "humidity_pct",
        "humidity_pulley": "humidity_pct"}
TIP_SPEED_M_S = 0.2   # tip sliding speed at 324 V (order of omega U_w), for the wear's sliding distance


def plan_of(seed: int) -> RigPlan:
    """The realistic tests' plan (``tests/rigcache.world_plan``): 1 ms step, 1 mm/s speed noise, 2 % scatter."""
    return RigPlan(step_s=1e-3, seed=seed, speed_noise_m_s=1e-3, run_scatter=0.02)


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 77, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "humidity_capillary":
        return {"B": float(rng.uniform(0.15, 0.20)),
                "RH": np.clip(45 + 15 * rng.standard_normal(n_runs), 20, 80)}
    if kind == "humidity_friction":
        return {"A": float(rng.uniform(0.08, 0.12)),
                "RH": np.clip(45 + 15 * rng.standard_normal(n_runs), 20, 80)}
    if kind == "chamber_temperature":
        return {"df_dT_b": float(rng.uniform(-30, -20)), "T": rng.uniform(18, 34, n_runs)}
    if kind == "lining_wear":
        return {"W": float(rng.uniform(0.10, 0.16)), "S0": float(rng.uniform(1.5, 3.0))}
    if kind == "vco_warmup":
        return {"D": rng.uniform(150, 400, n_runs), "tau": float(rng.uniform(0.08, 0.15))}
    if kind == "cable_preload":
        return {"angle_deg": float(rng.uniform(15, 25))}
    if kind == "humidity_pulley":
        return {"M": float(rng.uniform(0.25, 0.35)), "C": float(rng.uniform(8, 15)),
                "RH": np.clip(45 + 15 * rng.standard_normal(n_runs), 20, 80)}
    return {}


def bet_uptake(a: float, C: float) -> float:
    """The BET sorption isotherm: a polymer's water uptake (per monolayer) at the relative humidity ``a`` (0-1)."""
    return C * a / ((1 - a) * (1 - a + C * a))


def traverse(mp, nominal, plan, V0, load, d, T=None, f_of_t=None):
    """One traverse of the co-simulation (in-process engine) with the ambient ``T`` and drive frequency ``f_of_t``
    (a function of the run's time, or None: the plan's); the operator's supply is set at 25 degC and f0."""
    T = plan.ambient_degC if T is None else float(T)
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=V_s, f_s=f_of_t if f_of_t is not None else plan.f_drive_Hz, T=T, direction=d, m_load=load,
                 s0=s0)
    rec = ("Slider.s", "Stator.T_stator")
    return m.run(plan.max_run_s, record=rec, until=lambda mm: mm.value("Slider.at_stop") == d)


def load_in_slider_motor(mp, L: float, kind: str):
    """The motor ``mp`` for a run with load ``L`` whose load input will carry an extra force of ``kind``: the load's
    inertia moved into the slider's mass (``m' = m_s + load_inertia |L|``, ``load_inertia`` 0), and the guide's
    Coulomb levels ``mu_sd``, ``mu_ss`` times ``m_s / m'`` and its preload share ``kappa`` times ``m' / m_s``, so the
    guide's friction ``mu (kappa F_p + g m_s)`` is the motor's at every preload. Needs ``pulley_mu = 0``."""
    sl = mp.slider
    if sl.pulley_mu != 0:
        raise ValueError(f"{kind} moves the load's inertia into the slider: it needs pulley_mu = 0")
    m2 = sl.mass_kg + sl.load_inertia * abs(L)
    r = sl.mass_kg / m2
    return mp.replace(slider__mass_kg=m2, slider__load_inertia=0.0, slider__mu_sd=sl.mu_sd * r,
                      slider__mu_ss=sl.mu_ss * r, slider__kappa=sl.kappa / r)


def setting(kind: str, seed: int, draw_of) -> tuple:
    """``(plan, nominal, conds, factors, p, every)`` of an audit's experiment: the seed's plan, the realistic motor,
    the plan's runs ``(V0, load, direction)``, each run's contact factors, the kind's draw ``draw_of(kind, seed,
    n_runs)`` and the sampling stride of the co-simulation's output."""
    plan = plan_of(seed)
    nominal = load_motor(SYSTEM_MODELS_DIR / "realistic_motor.toml")
    conds = plan_runs(plan)
    factors = run_contact_factors(plan, len(conds))
    return plan, nominal, conds, factors, draw_of(kind, seed, len(conds)), sampling_every(plan)


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind (``"clean"``: none) and its truth."""
    plan, nominal, conds, factors, p, every = setting(kind, seed, draw)
    frames, t_next, S = [], 0.0, 0.0
    per_run = []
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        T, f_of_t = None, None
        if kind == "humidity_friction":
            mp = mp.replace(interface__mu_p=mp.interface.mu_p * (1 - p["A"] * math.tanh((p["RH"][k] - 45) / 8)))
        elif kind == "humidity_capillary":
            bump = math.exp(-((p["RH"][k] - 50) / 12) ** 2) - 0.5
            mp = mp.replace(interface__mu_p=mp.interface.mu_p * (1 + p["B"] * bump))
        elif kind == "chamber_temperature":
            mp = mp.replace(stator__df_dT_b_Hz_per_K=p["df_dT_b"])
            T = float(p["T"][k])
        elif kind == "lining_wear":
            mp = mp.replace(interface__mu_p=mp.interface.mu_p * (1 - p["W"] * (1 - math.exp(-S / p["S0"]))))
        elif kind == "vco_warmup":
            D, tau, f0 = float(p["D"][k]), p["tau"], plan.f_drive_Hz
            f_of_t = lambda t, D=D, tau=tau, f0=f0: f0 + D * math.exp(-t / tau)  # noqa: E731
        elif kind == "cable_preload":
            mp = mp.replace(stator__P0_N=mp.stator.P0_N + abs(L) * 9.81 * math.sin(math.radians(p["angle_deg"])))
        elif kind == "humidity_pulley":
            uptake = bet_uptake(p["RH"][k] / 100, p["C"]) / bet_uptake(0.45, p["C"])
            mp = mp.replace(slider__pulley_mu=p["M"] * uptake)
        r = traverse(mp, nominal, plan, V, L, d, T, f_of_t)
        idx = np.arange(0, len(r["time"]), every)
        t = r["time"][idx]
        f = (np.round([f_of_t(x) for x in t], 1) if f_of_t is not None else None)
        out = daq_frame(plan, t_next, k, t, r["Slider.s"][idx], V, L, d, f)
        noise = np.random.default_rng([seed, 78, k]).standard_normal(len(t))
        if kind == "chamber_temperature":
            out[dataio.TEMPERATURE] = np.round(r["Stator.T_stator"][idx] + 0.05 * noise, 2)
        if kind in ("humidity_friction", "humidity_capillary", "humidity_pulley"):
            out["humidity_pct"] = np.round(p["RH"][k] + 0.5 * noise, 2)
        frames.append(out)
        per_run.append({"run": k + 1, "mu_p": mp.interface.mu_p, "P0_N": mp.stator.P0_N, "S_m": S,
                        "pulley_mu": mp.slider.pulley_mu})
        S += TIP_SPEED_M_S * V / 324.0 * float(t[-1])
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return finish(kind, frames, per_run, p, nominal, plan)


def daq_frame(plan, t_next: float, k: int, t, s_m, V0, load, d, f_Hz=None, **extra) -> pd.DataFrame:
    """Run ``k + 1`` as the DAQ records it: the slider's position ``s_m`` [m] at the times ``t`` [s] of the run
    rounded to the encoder's resolution, the session clock offset by ``t_next`` [s], the speed the derivative of the
    recorded position, the drive frequency ``f_Hz`` per sample (default the plan's), then the ``extra`` columns."""
    pos = np.round(np.round(s_m / plan.encoder_resolution_m) * plan.encoder_resolution_m, 12)
    return pd.DataFrame({dataio.TIME: np.round(t_next + t, 9), dataio.RUN: k + 1, dataio.POSITION: pos,
                         dataio.VOLTAGE: V0, dataio.DIRECTION: d, dataio.LOAD: load,
                         dataio.SPEED: np.round(np.gradient(pos, t), 9),
                         dataio.FREQUENCY: np.full(len(t), plan.f_drive_Hz) if f_Hz is None else f_Hz, **extra})


def finish(kind: str, frames, per_run, p: dict, nominal, plan):
    """``(df, truth, nominal, plan)`` of an experiment: the runs' frames joined with the plan's speed noise, and the
    truth (the kind, its drawn parameters, the per-run values, the plan)."""
    df = add_speed_noise(pd.concat(frames, ignore_index=True), plan)
    params = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in p.items()}
    truth = {"blind_kind": kind, "parameters": params, "per_run": per_run, "plan": plan.__dict__}
    return df, truth, nominal, plan


def data_dir(kind: str, seed: int, cache: Path, make=None) -> Path:
    """The cached experiment of ``kind`` at ``seed`` (made by ``make(kind, seed)``, default :func:`experiment`,
    when absent; written to a partial folder first, then renamed)."""
    out = cache / f"{kind}_{seed}"
    if not (out / "train.csv").exists():
        df, truth, mp, plan = (make or experiment)(kind, seed)
        tmp = out.with_name(out.name + ".partial")
        shutil.rmtree(tmp, ignore_errors=True)
        write_experiment(df, tmp, mp, plan, truth)
        os.replace(tmp, out)
    return out


def default_cache() -> str:
    return str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "l1b2" / "blind_effects")


def loop_row(kind: str, seed: int, d: Path, **extra) -> tuple[dict, object]:
    """``(row, result)``: the close loop on the experiment in ``d`` (TRAIN, TEST) and its printed row: the first
    two traced regressors, the added effects, TEST free-run nrmse before and after [%], the channels considered
    and the significant ones, the message and the loop's CPU time [s]; ``extra(names)`` adds fields per kind
    (``names``: the channels considered)."""
    c0 = time.process_time()
    res = close_loop(load_measurements(d / "train.csv"), load_measurements(d / "test.csv"))
    cpu = time.process_time() - c0
    diag = res.diagnosis
    b = res.before["test"]["free_run"]["nrmse"]
    a = res.after["test"]["free_run"]["nrmse"] if res.after is not None else b
    considered = diag.get("channels_considered") or []
    names = [c.get("channel") for c in considered]
    row = {"kind": kind, "seed": seed, "traced": diag["traced_to"][:2],
           "added": [e["label"] for e in diag["effects"]], "before": round(100 * b, 3), "after": round(100 * a, 3),
           **{k: f(names, diag) for k, f in extra.items()}, "channels": names,
           "significant": [c.get("channel") for c in considered if c.get("significant")]
           + [f"{e['signal']} (run)" for c in considered for e in c.get("run_level") or [] if e.get("significant")],
           "message": diag["message"], "cpu_s": round(cpu, 1)}
    return row, res


def report_option(ap: argparse.ArgumentParser) -> None:
    """The ``--report FILE`` option of the loop's command lines (:func:`write_report`)."""
    ap.add_argument("--report", default="", help="write the close loop's whole result (report.json's content) here")


def write_report(path: str, res) -> None:
    """The close loop's whole result ``res`` (report.json's content) as JSON at ``path``; nothing when ``path`` is
    empty."""
    if path:
        Path(path).write_text(json.dumps(res.to_dict(), default=str))


def run_cli(argv, doc: str, kinds, make, row_extra):
    """The audits' command line: ``KIND SEED [--cache DIR] [--data-only] [--report FILE]``; ``make(kind, seed)``
    makes an experiment, ``row_extra(kind)`` gives the printed row's extra fields (see :func:`loop_row`)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("kind", choices=tuple(kinds) + ("clean",))
    ap.add_argument("seed", type=int)
    ap.add_argument("--cache", default=default_cache())
    ap.add_argument("--data-only", action="store_true", help="make (or find) the data and stop")
    report_option(ap)
    args = ap.parse_args(argv)
    d = data_dir(args.kind, args.seed, Path(args.cache), None if args.kind == "clean" else make)
    if args.data_only:
        print(d)
        return
    row, res = loop_row(args.kind, args.seed, d, **row_extra(args.kind))
    print(json.dumps(row))
    write_report(args.report, res)


def probe_args(argv, doc: str, kinds, modes) -> argparse.Namespace:
    """The probes' command line: ``KIND SEED MODE [--cache DIR] [--out DIR]`` (``kinds`` an audit's, and ``clean``;
    ``modes`` the probe's changes of the files)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("kind", choices=tuple(kinds) + ("clean",))
    ap.add_argument("seed", type=int)
    ap.add_argument("mode", choices=tuple(modes))
    ap.add_argument("--cache", default=default_cache())
    ap.add_argument("--out", default="", help="the changed copy's folder (default: a temporary one)")
    return ap.parse_args(argv)


def probe_copy(args: argparse.Namespace, make) -> tuple[Path, Path]:
    """``(src, dst)``: the cached experiment of ``args.kind`` at ``args.seed`` (made by ``make`` when absent, the
    clean one for ``clean``) and a fresh copy of it in ``args.out`` (default: a new temporary folder)."""
    src = data_dir(args.kind, args.seed, Path(args.cache), None if args.kind == "clean" else make)
    dst = Path(args.out or tempfile.mkdtemp(prefix="l1b2_probe_"))
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(src, dst)
    return src, dst


def print_channel_evidence(res, prefix, keys: tuple, run_keys: tuple) -> None:
    """Print one JSON line per channel the close loop ``res`` considered whose name starts with ``prefix`` (None or
    "": none): the record's ``keys`` and its run-level signals' ``run_keys``."""
    for c in res.diagnosis.get("channels_considered") or []:
        if prefix and str(c.get("channel", "")).startswith(prefix):
            print(json.dumps({k: c.get(k) for k in keys}
                             | {"run_level": [{k: e.get(k) for k in run_keys} for e in c.get("run_level") or []]},
                             default=str))


def want_fields(channels: dict, want: dict):
    """``row_extra`` of :func:`run_cli` for an audit with a pass rule: the kind's ``channel``, the regressors
    accepted as the effect's (``want``) and every traced regressor (``traced_all``)."""
    return lambda kind: {"channel": lambda names, diag: channels.get(kind),
                         "want": lambda names, diag: list(want.get(kind, ())),
                         "traced_all": lambda names, diag: list(diag["traced_to"])}


def accepted_by(want: dict, not_want: dict, kind: str, name: str) -> bool:
    """Whether the traced regressor ``name`` is ``kind``'s: it holds a word of ``want[kind]`` and none of
    ``not_want[kind]``."""
    n = str(name)
    return any(w in n for w in want.get(kind, ())) and not any(w in n for w in not_want.get(kind, ()))


def audit_verdict(row: dict, b0: dict, decoys: dict, accepted) -> dict:
    """The audits' pass rule on a printed row (``kind``, ``seed``, ``traced``, ``traced_all``, ``before``, ``after``
    in %): ``bound`` = sqrt(b0^2 + (b^2 - b0^2) / 4) with ``b0[seed]`` the clean control's before (a decoy's: 1.02 b),
    ``attributed`` (``accepted(kind, name)`` for one of the first two traced; for a decoy of ``decoys`` (kind ->
    column), its column nowhere in ``traced_all``) and ``passes`` (both, and ``a <= bound``)."""
    kind, b, a = row["kind"], float(row["before"]), float(row["after"])
    if kind in decoys:
        bound = 1.02 * b
        attributed = not any(decoys[kind] in str(x) for x in row.get("traced_all") or row["traced"])
    else:
        b_0 = b0[int(row["seed"])]
        bound = math.sqrt(b_0 ** 2 + (b ** 2 - b_0 ** 2) / 4.0)
        attributed = any(accepted(kind, x) for x in row["traced"][:2])
    return {"bound": bound, "attributed": attributed, "passes": attributed and a <= bound}


def run_audit(argv, doc: str, kinds, make, channels: dict, want: dict, not_want: dict, accepted=None) -> None:
    """:func:`run_cli` for an audit whose pass rule reads the first two traced regressors: the row's
    :func:`want_fields` and ``accepted_in_first_two`` (``accepted(kind, name)`` of one of them; default
    :func:`accepted_by` of ``want`` and ``not_want``)."""
    fields = want_fields(channels, want)
    accept = accepted or (lambda kind, name: accepted_by(want, not_want, kind, name))

    def extra(kind):
        out = fields(kind)
        out["accepted_in_first_two"] = lambda names, diag: any(accept(kind, x) for x in diag["traced_to"][:2])
        return out
    run_cli(argv, doc, kinds, make, extra)


def probe_loop(args, dst: Path, prefix) -> tuple[dict, object]:
    """The close loop on a probe's changed copy ``dst``: prints its row (with ``traced_all``) and the evidence on
    the channels named ``prefix*`` (:func:`print_channel_evidence`); returns ``(row, result)``."""
    row, res = loop_row(f"{args.kind}({args.mode})", args.seed, dst,
                        traced_all=lambda names, diag: list(diag["traced_to"]))
    print(json.dumps(row))
    print_channel_evidence(res, prefix, ("channel", "significant", "p_value", "cv_gain", "best"),
                           ("signal", "significant", "p_value", "cv_gain", "dominated_by"))
    return row, res


def probe_truth_main(argv, doc: str, audit, modes, changed, column: dict, settings: dict) -> None:
    """A probe's whole command (:func:`probe_args`): the audit's case copied (:func:`probe_copy`), each part
    rewritten by ``changed(frame, mode, truth)`` (``truth``: the case's ``rig_truth.json``), the close loop run with
    ``settings[mode]`` (none when absent) and its row and the evidence on ``column[mode]`` printed
    (:func:`probe_loop`). ``audit``: the audit's module (``KINDS``, ``experiment``)."""
    global close_loop
    args = probe_args(argv, doc, audit.KINDS, modes)
    src, dst = probe_copy(args, audit.experiment)
    truth = json.loads((src / "rig_truth.json").read_text())
    for part in ("train", "test"):
        changed(pd.read_csv(src / f"{part}.csv"), args.mode, truth).to_csv(dst / f"{part}.csv", index=False)
    if args.mode in settings:
        close_loop = functools.partial(close_loop, **settings[args.mode])
    probe_loop(args, dst, column[args.mode])


def channel_field(channels: dict):
    """``row_extra`` of :func:`run_cli` for an audit whose kinds each act through one logged channel: the row's
    ``channel`` field is ``channels[kind]`` (None for a kind without one, and for ``clean``)."""
    return lambda kind: {"channel": lambda names, diag: channels.get(kind)}


def main(argv=None):
    def extra(kind):
        ch = CHANNEL.get(kind)
        return {"channel_considered": lambda names, diag: None if ch is None else ch in names}
    run_cli(argv, __doc__, KINDS, experiment, extra)

if __name__ == "__main__":
    main()
