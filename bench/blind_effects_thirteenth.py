#!/usr/bin/env python
"""A thirteenth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the twelve earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_twelfth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``tip_edge_tilt`` -- logged ``stator_tilt_mrad`` per sample, an inclinometer on the stator holder (0.02 mrad of
  noise, 0.01 mrad resolution). A goniometer under the holder sets the stator's tilt about the friction bar's axis
  per run (a design factor, uniform in -2.5..+2.5 mrad). The tip's flat face sits fully on the composite lining while
  the tilt's rise across the face stays within the lining's compression, ``|theta| <= theta_c`` (``theta_c`` drawn
  in 0.8-1.3 mrad); past it the tip rides on its edge and the contact narrows as ``theta_c / |theta|``, so the mean
  pressure grows as ``|theta| / theta_c``. A polymer lining's friction coefficient is an interfacial shear over the
  pressure plus a ploughing term, ``tau0 / p + alpha``: its shear share ``a`` (drawn in 0.25-0.35 at the flat face's
  pressure) falls as ``1 / p``, so the slip friction is ``mu_p (1 - a + a min(1, theta_c / |theta|))``: flat up to
  the threshold, an inverse law past it, even in the tilt (1 at a flat seat down to about 0.8 at 2.5 mrad).
* ``matching_cap_swap`` -- no column; a change of the rig between runs. The drive's matching capacitor ``C1`` (a
  3.0 nF part) cracks after a run drawn in 20-52 (the k-th run, 1-based); the operator replaces it from the drawer
  with an E24 2.4 nF or 2.7 nF part (one of the two drawn at random, its actual value within +-5 % drawn uniformly)
  and goes on with the session's supply table, computed for the old part: from run k + 1 on, the tank's gain and so
  V0 differ from the logged ``voltage_V`` (the tank's gain by -3..-16 % over the parts). The repair takes a rest of
  120-300 s (drawn) before run k + 1, which only the session clock shows.
* ``repair_pause_control`` -- the swap's control, not a kind of its own: the same draw (the same long rest before the
  same run) with the original capacitor. It tells what the rest alone does to the loop.
* ``mains_dropout`` -- logged ``mains_V`` per sample, the lab's mains voltage read by the drive's power analyser
  (0.2 V of noise, 0.1 V resolution); through the drive circuit, a product of two logged channels under a threshold.
  The drive's DC bus comes from a bench supply whose linear regulator feeds off a transformer and rectifier: its
  raw DC is ``U230 mains / 230 V`` (``U230`` drawn in 64-68 V) and the regulator needs a headroom ``h`` (drawn in
  1.5-2.5 V). The mains differs between runs as the building's load changes (``230 + 7 z`` V, z standard normal,
  clipped to 212-248 V, per run). The operator sets the supply for the plan's V0 (``V_set``: 45.6 V at 220 V up to
  67.1 V at 324 V), and the supply delivers ``min(V_set, U230 mains / 230 V - h)``: the runs at high V0 and low
  mains drop out of regulation and their V0 falls with the mains; the other runs are untouched. ``voltage_V`` logs
  the plan's V0.
* ``slider_accel_decoy`` -- a decoy, no effect on the motor: logged ``slider_accel_g`` per sample, a MEMS
  accelerometer on the slider (its 2 g are part of the slider's mass) along the motion. It reads the slider's
  acceleration through its first-order anti-alias filter at ``f_c`` (drawn in 40-80 Hz; from 0 at each run's start,
  the slider at rest), in units of g (9.81 m/s^2), plus a bias ``b`` (drawn in -0.02..+0.02 g), 0.005 g of noise
  and 0.001 g resolution: a consequence of the motion (its start, the speed's changes along the stroke), which acts
  on nothing. It must not be traced.

Pass rule (fixed before any loop ran; the eighth to twelfth audits'): a kind passes when a regressor of ``WANT`` is
among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before and
after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``slider_accel_g`` is nowhere in ``traced_all`` and ``a <=
1.02 b``. ``WANT``: the inclinometer's column for the tilt (a name holding ``stator_tilt``); the mains column for the
dropout (a name holding ``mains``; the voltage alone is not accepted: the logged V0 is right for most runs); for the
swap, a regressor of the session's clock or order or of the rests between runs (its name holds ``time``, ``order``,
``index``, ``count``, ``since``, ``session``, ``pause``, ``rest`` or ``gap``, and not ``time_in_run``: the run's own
clock carries no change between runs). The control has no pass rule (``WANT`` empty; it is reported, not judged).

Usage: python bench/blind_effects_thirteenth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run nrmse before
and after, channels considered, CPU of the close loop by ``time.process_time``), plus ``traced_all`` (every traced
regressor) and ``want`` (the regressors accepted as the effect's).
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.cosim.engine import InProcessMotor  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("tip_edge_tilt", "matching_cap_swap", "mains_dropout", "slider_accel_decoy", "repair_pause_control")
#: a kind that draws from another kind's stream (the same draw, no effect)
STREAM = {"repair_pause_control": "matching_cap_swap"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"tip_edge_tilt": "stator_tilt_mrad", "matching_cap_swap": None, "mains_dropout": "mains_V",
           "slider_accel_decoy": "slider_accel_g", "repair_pause_control": None}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"tip_edge_tilt": ("stator_tilt",),
        "matching_cap_swap": ("time", "order", "index", "count", "since", "session", "pause", "rest", "gap"),
        "mains_dropout": ("mains",),
        "slider_accel_decoy": (),
        "repair_pause_control": ()}
#: names that hold a word of ``WANT`` but are not accepted (the run's own clock)
NOT_WANT = {"matching_cap_swap": ("time_in_run",)}
C1_SPARES_NF = (2.4, 2.7)   # the drawer's E24 parts
G_ACC = 9.81                # m/s^2 per g


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the swap's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 151, KINDS.index(src) if src in KINDS else 99])
    if kind == "tip_edge_tilt":
        return {"theta_c_mrad": float(rng.uniform(0.8, 1.3)), "a": float(rng.uniform(0.25, 0.35)),
                "theta_mrad": rng.uniform(-2.5, 2.5, n_runs)}
    if src == "matching_cap_swap":
        k = int(rng.integers(20, 53))
        part = float(C1_SPARES_NF[int(rng.integers(0, 2))] * rng.uniform(0.95, 1.05))
        p = {"k_swap": k, "C1_new_nF": part, "rest_s": float(rng.uniform(120.0, 300.0))}
        if kind == "repair_pause_control":
            p["C1_new_nF"] = None
        return p
    if kind == "mains_dropout":
        return {"U230_V": float(rng.uniform(64.0, 68.0)), "h_V": float(rng.uniform(1.5, 2.5)),
                "mains_V": np.clip(230.0 + 7.0 * rng.standard_normal(n_runs), 212.0, 248.0)}
    if kind == "slider_accel_decoy":
        return {"f_c_Hz": float(rng.uniform(40.0, 80.0)), "bias_g": float(rng.uniform(-0.02, 0.02))}
    return {}


def edge_factor(theta_mrad, theta_c_mrad: float, a: float):
    """The slip friction's factor at the tilt ``theta_mrad``: ``1 - a + a min(1, theta_c / |theta|)``."""
    t = np.abs(np.asarray(theta_mrad, float))
    ratio = np.where(t > theta_c_mrad, theta_c_mrad / np.maximum(t, 1e-300), 1.0)
    return 1.0 - a + a * ratio


def supplied_V(V_set, mains_V, U230_V: float, h_V: float):
    """The bench supply's output: ``min(V_set, U230 mains / 230 V - h)``."""
    return np.minimum(np.asarray(V_set, float), U230_V * np.asarray(mains_V, float) / 230.0 - h_V)


def c1_of_run(p: dict, k: int, C1_F: float) -> float:
    """Run ``k``'s (0-based) matching capacitor [F]: the original ``C1_F`` up to the swap's run ``k_swap`` (1-based,
    the cracked part's last run), the spare ``C1_new_nF`` after it (the control keeps the original)."""
    if p.get("C1_new_nF") is None or k < p["k_swap"]:
        return float(C1_F)
    return float(p["C1_new_nF"]) * 1e-9


def rest_before(p: dict, k: int, pause_s: float) -> float:
    """The rest [s] before run ``k`` (0-based) is taken, after the run before: the repair's rest before the first run
    after the swap, the plan's pause otherwise."""
    return float(p["rest_s"]) if "k_swap" in p and k == p["k_swap"] else float(pause_s)


def accelerometer_g(t, v, f_c_Hz: float, bias_g: float):
    """The accelerometer's reading [g] (no noise, no rounding) of the speed ``v`` [m/s] at the times ``t`` [s]: the
    acceleration ``dv/dt`` (``numpy.gradient``) through a first-order low-pass at ``f_c`` from 0 (exact for an input
    held over each step), over ``9.81 m/s^2``, plus the bias."""
    t, acc = np.asarray(t, float), np.gradient(np.asarray(v, float), np.asarray(t, float))
    out = np.zeros_like(acc)
    w = 2.0 * np.pi * f_c_Hz
    for i in range(1, len(t)):
        e = np.exp(-w * (t[i] - t[i - 1]))
        out[i] = e * out[i - 1] + (1.0 - e) * acc[i - 1]
    return out / G_ACC + bias_g


def traverse(mp, nominal, plan, V0, load, d, V_s=None):
    """One traverse at the plan's frequency with the supply ``V_s`` (default: the operator's setting for ``V0`` from
    the nominal drive at 25 degC)."""
    if V_s is None:
        V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=d, m_load=load, s0=s0)
    return m.run(plan.max_run_s, record=("Slider.s", "Slider.v"),
                 until=lambda mm: mm.value("Slider.at_stop") == d)


def run_setup(kind: str, mp, nominal, plan, p: dict, k: int, V0: float):
    """``(motor, V_s)`` of run ``k`` of ``kind`` from its scattered motor ``mp`` (``V_s`` None: the operator's)."""
    if kind == "tip_edge_tilt":
        fac = float(edge_factor(p["theta_mrad"][k], p["theta_c_mrad"], p["a"]))
        return mp.replace(interface__mu_p=mp.interface.mu_p * fac), None
    if kind in ("matching_cap_swap", "repair_pause_control"):
        return mp.replace(driver__C1_F=c1_of_run(p, k, mp.driver.C1_F)), None
    if kind == "mains_dropout":
        V_set = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
        return mp, float(supplied_V(V_set, p["mains_V"][k], p["U230_V"], p["h_V"]))
    return mp, None


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next = [], [], 0.0
    for k, (V, L, d) in enumerate(conds):
        if k > 0:
            t_next += rest_before(p, k, plan.pause_s) - plan.pause_s
        mp, V_s = run_setup(kind, scattered_motor(nominal, factors[k]), nominal, plan, p, k, V)
        r = traverse(mp, nominal, plan, V, L, d, V_s)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 152, k]).standard_normal(len(t))
        if kind == "tip_edge_tilt":
            extra["stator_tilt_mrad"] = np.round(p["theta_mrad"][k] + 0.02 * noise, 2)
        elif kind == "mains_dropout":
            extra["mains_V"] = np.round(p["mains_V"][k] + 0.2 * noise, 1)
        elif kind == "slider_accel_decoy":
            acc = accelerometer_g(r["time"], r["Slider.v"], p["f_c_Hz"], p["bias_g"])[idx]
            extra["slider_accel_g"] = np.round(acc + 0.005 * noise, 3)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p, "C1_F": mp.driver.C1_F,
                        "V_s": V_s, "t_start_s": t_next, "duration_s": float(r["time"][-1])})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def accepted(kind: str, name: str) -> bool:
    """Whether the traced regressor ``name`` is the kind's (a word of ``WANT`` and none of ``NOT_WANT``)."""
    return be.accepted_by(WANT, NOT_WANT, kind, name)


def main(argv=None):
    be.run_audit(argv, __doc__, KINDS, experiment, CHANNEL, WANT, NOT_WANT)


if __name__ == "__main__":
    main()
