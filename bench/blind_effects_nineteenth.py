#!/usr/bin/env python
"""A nineteenth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of
the loop and no kind of the eighteen earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_eighteenth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``hardstop_gib_reseat`` -- no column; a change between runs set by the previous runs' own outcome. The stator
  holder slides toward the friction bar on a dovetail, pushed by the preload spring onto its set screw and locked
  there by a gib. The drive's vibration makes the locked holder creep back on its dovetail, a little each run, so
  the preload relaxes with the runs since the holder last sat on its screw: ``P0 (1 - R (1 - exp(-n / n0)))``
  (``R`` drawn in 20-30 %, ``n0`` in 2-4 runs). The slider ends each run against its rubber end stop; a run that
  arrives hard (its arrival speed, the mean over its last 5 mm before the stop, at ``v_hard`` or more, drawn in
  0.21-0.25 m/s) jolts the frame, the gib lets go for an instant and the spring pushes the holder back onto its
  screw: ``n`` is 0 for the run after a hard arrival and grows by one each run after a soft one (0 for the first
  run: the operator set the preload before the session). The state is a function of the runs' own speeds at the
  stop (so of V0, the load, the direction and the state itself), not of time, not of blocks of files and not of the
  plan's V0 sequence alone.
* ``hardstop_gib_logged`` -- the reseat's control, not a kind of its own: the same draw and the same motion as
  ``hardstop_gib_reseat`` at the seed, with the holder's creep logged as ``holder_walk_um`` (``P0 R (1 - exp(-n /
  n0)) / k_p`` in um, ``P0`` and ``k_p`` the motor's preload and its spring's stiffness; per sample, 0.1 um
  resolution, no noise), as a dial gauge on the holder would read it. What the loop makes of the state logged tells
  the hidden state's loss.
* ``glovebox_oxygen`` -- logged ``o2_pct`` per sample, a zirconia oxygen analyser in the glove box the rig runs in
  (1 % of its reading as noise per sample, 0.01 %-point resolution). An atmosphere study: before each run the operator
  sets the box's oxygen with a nitrogen bleed, log-uniform in 0.1-20.9 % per run, and waits for the reading to
  settle. The slider's crossed-roller guide runs dry (a vacuum-grade guide), and the oxide film that oxygen keeps on
  its rollers and rails lowers their friction: with the film's coverage a Langmuir isotherm of the oxygen share ``x``,
  ``theta(x) = x / (x + x_h)`` (``x_h`` drawn in 0.5-2 %), the guide's Coulomb levels ``mu_sd`` and ``mu_ss`` are
  ``(1 + A (1 - theta(x))) / (1 + A (1 - theta(20.9)))`` times the motor's (``A`` drawn in 0.15-0.30): the motor's own
  in air, up to ``1 + A`` times it at no oxygen.
* ``lining_wlf_grosch`` -- logged ``lining_temp_C`` per sample, a thermocouple in the friction bar under its lining
  (0.05 degC of noise per sample, 0.01 degC resolution). A temperature study: the bar sits on a heater plate whose set
  point the operator changes before each run (uniform in 15-45 degC per run; the drive and the stator stay at the
  lab's 25 degC). The polymer lining's friction follows Grosch's master curve: a function of the log of its sliding
  speed shifted by the Williams-Landel-Ferry factor, ``x = log10(v_t / 0.2 m/s) + log10 a_T``, ``log10 a_T = -8.86 (T
  - 25) / (101.6 + T - 25)`` (T in degC, referred to 25 degC), ``v_t = 0.2 m/s V0 / 324 V`` the tip's sliding speed,
  ``G(x) = 8 + exp(-(x - x_p)^2 / (2 w^2))``, and the slip friction is ``mu_p G(x(T, V0)) / G(x(25, V0))``: the
  motor's own at 25 degC at every V0. The peak's place ``x_p`` is ``log10 a_T`` at ``T_pk`` (drawn in 30-40 degC) and
  its width ``w`` is drawn in 0.6-0.9 decades. The law rises and falls with T (a bell over the lining's transition),
  and the V0 shifts it by up to 0.17 decade.
* ``weight_laser_decoy`` -- a decoy, no effect on the motor: logged ``weight_height_mm`` per sample, a laser
  triangulation sensor under the -position end's pulley, which carries the positive loads (the negative loads hang
  from the other end's pulley). It reads the height of the hanging weight's bottom above it, ``z_0 + 1000 (s -
  s_min) - h_m 1000 m`` [mm] for a positive load ``m`` [kg] (the cable lifts the weight as the slider moves toward
  +position; the hooked brass cylinders grow by ``h_m`` per gram; ``z_0`` drawn in 40-60 mm, ``h_m`` in 0.25-0.35
  mm/g), and its far limit, 200 mm, when no weight hangs there (a negative or no load); 0.02 mm of noise, 0.01 mm
  resolution. It follows the position and the load; a sensor's reading acts on nothing, and it must not be traced.

Pass rule (fixed before any loop ran; the eighth to eighteenth audits'): a kind passes when a regressor of ``WANT``
is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before
and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``weight_height`` is nowhere in ``traced_all`` and ``a <=
1.02 b``. ``WANT``: the analyser's column for the oxygen (a name holding ``o2``); the thermocouple's column for the
lining (a name holding ``lining_temp``); for the reseat, a regressor of the runs' own motion before (its name holds
``speed``, ``dur`` or ``arriv`` together with one of ``prev``, ``last``, ``lag``, ``hist``, ``since``, ``ewm``,
``mean`` or ``avg``), or one holding ``gib``, ``reseat``, ``hard`` or ``holder_walk``, and none of the load's or V0's
(``load``, ``voltage``): the state follows the runs' arrivals at the stop, not the plan's inputs. The control is
reported with its own column (``holder_walk_um``) but not counted.

Usage: python bench/blind_effects_nineteenth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one of
the above or clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run
nrmse before and after, channels considered, CPU of the close loop by ``time.process_time``), plus ``traced_all``
(every traced regressor), ``want`` (the regressors accepted as the effect's) and ``accepted_in_first_two``.
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("hardstop_gib_reseat", "glovebox_oxygen", "lining_wlf_grosch", "weight_laser_decoy",
         "hardstop_gib_logged")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"hardstop_gib_logged": "hardstop_gib_reseat"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"hardstop_gib_reseat": None, "glovebox_oxygen": "o2_pct", "lining_wlf_grosch": "lining_temp_C",
           "weight_laser_decoy": "weight_height_mm", "hardstop_gib_logged": "holder_walk_um"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran); the reseat's
#: need a word of ``HISTORY`` and one of ``MOTION``, or one of ``STATE``
WANT = {"hardstop_gib_reseat": ("speed", "dur", "arriv", "gib", "reseat", "hard", "holder_walk"),
        "glovebox_oxygen": ("o2",),
        "lining_wlf_grosch": ("lining_temp",),
        "weight_laser_decoy": (),
        "hardstop_gib_logged": ("holder_walk",)}
MOTION = ("speed", "dur", "arriv")
HISTORY = ("prev", "last", "lag", "hist", "since", "ewm", "mean", "avg")
STATE = ("gib", "reseat", "hard", "holder_walk")
#: names that hold a word of ``WANT`` but are not accepted (the plan's inputs' histories)
NOT_WANT = {"hardstop_gib_reseat": ("load", "voltage")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"weight_laser_decoy": "weight_height"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
ARRIVAL_M = 0.005            # the arrival speed: the mean over the last 5 mm before the stop
O2_RANGE = (0.1, 20.9)       # the box's oxygen share per run [%], log-uniform
O2_AIR = 20.9                # air's oxygen share [%]: the motor's own guide
LINING_T_RANGE = (15.0, 45.0)  # the heater plate's set point per run [degC]
T_REF = 25.0                 # the lab's temperature: the motor's own lining
WLF_C1, WLF_C2 = 8.86, 101.6
TIP_SPEED_M_S = 0.2          # the tip's sliding speed at 324 V (as bench/blind_effects.py)
GROSCH_BASE = 8.0            # the master curve's share off the peak
LASER_FAR_MM = 200.0         # the laser's far limit: no weight over it


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the reseat's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 211, KINDS.index(src) if src in KINDS else 99])
    if src == "hardstop_gib_reseat":
        return {"R": float(rng.uniform(0.20, 0.30)), "n0": float(rng.uniform(2.0, 4.0)),
                "v_hard": float(rng.uniform(0.21, 0.25))}
    if kind == "glovebox_oxygen":
        return {"x_h": float(rng.uniform(0.5, 2.0)), "A": float(rng.uniform(0.15, 0.3)),
                "o2": np.exp(rng.uniform(math.log(O2_RANGE[0]), math.log(O2_RANGE[1]), n_runs))}
    if kind == "lining_wlf_grosch":
        return {"T_pk": float(rng.uniform(30.0, 40.0)), "w": float(rng.uniform(0.6, 0.9)),
                "T": rng.uniform(*LINING_T_RANGE, n_runs)}
    if kind == "weight_laser_decoy":
        return {"z0_mm": float(rng.uniform(40.0, 60.0)), "h_m_mm_per_g": float(rng.uniform(0.25, 0.35))}
    return {}


def seat_factor(n: int, R: float, n0: float) -> float:
    """The preload's share ``1 - R (1 - exp(-n / n0))`` after ``n`` runs since the holder last sat on its screw."""
    return 1.0 - R * (1.0 - math.exp(-n / n0))


def arrival_speed(t, s, d: int, stop: float) -> float:
    """The run's arrival speed [m/s] at its stop ``stop`` [m] (``d`` its direction): the last 5 mm before the
    stop's position over the time they took, from the first sample within 5 mm to the run's last."""
    t, s = np.asarray(t, float), np.asarray(s, float)
    i = int(np.argmax(d * (s - stop) >= -ARRIVAL_M))
    return abs(float(s[-1] - s[i])) / float(t[-1] - t[i])


def next_n(n: int, v_arrival: float, v_hard: float) -> int:
    """The runs since the holder sat on its screw for the run after one with ``n`` and arrival speed
    ``v_arrival``: 0 after a hard arrival (``>= v_hard``), else ``n + 1``."""
    return 0 if v_arrival >= v_hard else n + 1


def walk_um(n: int, P0: float, k_p: float, R: float, n0: float) -> float:
    """The holder's creep back from its screw [um]: ``P0 R (1 - exp(-n / n0)) / k_p``."""
    return 1e6 * P0 * R * (1.0 - math.exp(-n / n0)) / k_p


def coverage(x, x_h: float):
    """The oxide film's coverage at the oxygen share ``x`` [%]: ``x / (x + x_h)``."""
    x = np.asarray(x, float)
    return x / (x + x_h)


def guide_factor(x, x_h: float, A: float):
    """The guide's Coulomb levels' share at the oxygen share ``x``: ``(1 + A (1 - theta(x))) / (1 + A (1 -
    theta(20.9)))``."""
    return (1.0 + A * (1.0 - coverage(x, x_h))) / (1.0 + A * (1.0 - coverage(O2_AIR, x_h)))


def log_aT(T):
    """WLF's shift ``log10 a_T = -8.86 (T - 25) / (101.6 + T - 25)`` (T in degC)."""
    dT = np.asarray(T, float) - T_REF
    return -WLF_C1 * dT / (WLF_C2 + dT)


def grosch_x(T, V0):
    """The master curve's abscissa ``log10(v_t / 0.2 m/s) + log10 a_T`` with ``v_t = 0.2 m/s V0 / 324 V``."""
    return np.log10(np.asarray(V0, float) / 324.0) + log_aT(T)


def grosch_G(x, x_p: float, w: float):
    """Grosch's master curve ``8 + exp(-(x - x_p)^2 / (2 w^2))``."""
    return GROSCH_BASE + np.exp(-(np.asarray(x, float) - x_p) ** 2 / (2.0 * w * w))


def lining_factor(T, V0, T_pk: float, w: float):
    """The slip friction's share ``G(x(T, V0)) / G(x(25, V0))``, the peak at ``x_p = log10 a_T(T_pk)``."""
    x_p = float(log_aT(T_pk))
    return grosch_G(grosch_x(T, V0), x_p, w) / grosch_G(grosch_x(T_REF, V0), x_p, w)


def laser_reading_mm(s_m, load: float, p: dict):
    """The laser's reading [mm] at the positions ``s_m`` (no noise, no rounding): ``z_0 + 1000 (s + 0.021) - h_m 1000
    m`` for a positive load, else 200 mm."""
    s = np.asarray(s_m, float)
    if load <= 0:
        return np.full(s.shape, LASER_FAR_MM)
    return p["z0_mm"] + 1000.0 * (s + 0.021) - p["h_m_mm_per_g"] * 1000.0 * load


def run_motor(kind: str, mp, p: dict, k: int, V0: float, n: int = 0):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``V0`` the run's, ``n`` the reseat's runs since
    the screw)."""
    if STREAM.get(kind, kind) == "hardstop_gib_reseat":
        return mp.replace(stator__P0_N=mp.stator.P0_N * seat_factor(n, p["R"], p["n0"]))
    if kind == "glovebox_oxygen":
        g = float(guide_factor(p["o2"][k], p["x_h"], p["A"]))
        return mp.replace(slider__mu_sd=mp.slider.mu_sd * g, slider__mu_ss=mp.slider.mu_ss * g)
    if kind == "lining_wlf_grosch":
        return mp.replace(interface__mu_p=mp.interface.mu_p * float(lining_factor(p["T"][k], V0, p["T_pk"], p["w"])))
    return mp


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    reseat = STREAM.get(kind, kind) == "hardstop_gib_reseat"
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next, n = [], [], 0.0, 0
    for k, (V, L, d) in enumerate(conds_run):
        mp = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, V, n)
        r = be.traverse(mp, nominal, plan, V, L, d)
        stop = mp.slider.s_max_m if d > 0 else mp.slider.s_min_m
        v_arr = arrival_speed(r["time"], r["Slider.s"], d, stop)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 212, k]).standard_normal(len(t))
        if kind == "glovebox_oxygen":
            extra["o2_pct"] = np.round(p["o2"][k] * (1.0 + 0.01 * noise), 2)
        elif kind == "lining_wlf_grosch":
            extra["lining_temp_C"] = np.round(p["T"][k] + 0.05 * noise, 2)
        elif kind == "weight_laser_decoy":
            extra["weight_height_mm"] = np.round(laser_reading_mm(s, L, p) + 0.02 * noise, 2)
        elif kind == "hardstop_gib_logged":
            w = walk_um(n, nominal.stator.P0_N, nominal.stator.preload_stiffness_N_per_m, p["R"], p["n0"])
            extra["holder_walk_um"] = np.full(len(t), round(w, 1))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p, "mu_sd": mp.slider.mu_sd,
                        "mu_ss": mp.slider.mu_ss, "n_since_seat": n if reseat else 0, "v_arrival_m_s": v_arr,
                        "t_start_s": t_next, "duration_s": float(r["time"][-1])})
        if reseat:
            n = next_n(n, v_arr, p["v_hard"])
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def accepted(kind: str, name: str) -> bool:
    """Whether the traced regressor ``name`` is the kind's: for the reseat, a word of ``STATE``, or one of
    ``MOTION`` with one of ``HISTORY``, and none of ``NOT_WANT``; for the others a word of ``WANT``."""
    n = str(name)
    if kind == "hardstop_gib_reseat":
        ok = any(w in n for w in STATE) or (any(w in n for w in MOTION) and any(w in n for w in HISTORY))
        return ok and not any(w in n for w in NOT_WANT[kind])
    return be.accepted_by(WANT, NOT_WANT, kind, name)


def verdict(row: dict) -> dict:
    """The pass rule on a printed row (``kind``, ``seed``, ``traced``, ``traced_all``, ``before``, ``after`` in %):
    ``bound`` = sqrt(b0^2 + (b^2 - b0^2) / 4) (the decoy's: 1.02 b), ``attributed`` (a regressor of ``WANT`` among
    the first two; for the decoy, its column nowhere in ``traced_all``) and ``passes`` (both, ``a <= bound``)."""
    return be.audit_verdict(row, B0, DECOY, accepted)


def main(argv=None):
    be.run_audit(argv, __doc__, KINDS, experiment, CHANNEL, WANT, NOT_WANT, accepted)


if __name__ == "__main__":
    main()
