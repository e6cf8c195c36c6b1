#!/usr/bin/env python
"""A twenty-eighth blind audit of the close loop: four more kinds that no injection of the rig and no kind of the
twenty-seven earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_twentyseventh.py``, ``bench/blind_effects_stamps.py``)
names, written without the close loop's code, its effect families and its decision records.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row and
``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan
at a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). Every kind but the decoy sets FMU parameters
per run (the preload, B2's coupling, the modes; ``bench/blind_effects_fifth.py``'s ``traverse``), the decoy none;
the speed is always the DAQ's derivative of the recorded position. Each kind draws from one random stream of its
seed. The kinds:

* ``preload_cell_crosstalk`` -- logged ``preload_cell_N`` per sample, a button load cell under the stator holder's
  preload spring (5 mN of noise, 1 mN resolution): a cause read through a sensor that also echoes the motion. A
  preload study: the spring sits on a fine-threaded plug that the operator turns before each run to a set force
  ``P_set`` drawn uniform in 5.0-7.7 N (about the design's 5-8 N; the plug's scale is not logged), which takes the
  place of the motor's ``P0`` (the world's run-to-run preload scatter ``f`` kept as a factor of it). The holder
  follows the friction bar's deviation along the stroke, so the spring pushes with ``P(s) = P_set f + k_pre
  delta(s)`` (the motor's own law: 5.8-7.7 N along the stroke at the motor's 6.35 N) and the contact carries
  ``F_p = alpha0 P(s)``; the cell reads ``P(s)``. It also takes, as a side load, the holder's reaction to the tip's
  drive force ``F_d`` (the period-mean force on the slider, positive toward +position: up to 2.7 N at a start and
  0.8-1.9 N along a run, the guide's damping and friction, the load and the slider's inertia, so it follows the
  speed within each run), and its cross-talk ``x`` (``|x|`` drawn in 1.5-3.5 %, its sign at random: the cell's
  off-axis sensitivity) adds ``x F_d`` to the reading (up to +-96 mN). So the logged reading is ``P_set f + k_pre
  delta(s) + x F_d``: the run's setting, which acts through the contact's preload, the slider's position through the
  bar (the same law in every run) and an echo of its drive force that acts on nothing. The preload's effect on the
  speed changes with V0 and the load (+5 % of it: -0.5 to +2.9 % of speed at four conditions of the motor's own;
  -28 to +16 % over the runs of seeds 1-3). The cell's compliance in series with the spring is left out.
* ``carriage_anemometer_decoy`` -- a decoy, no effect on the motor: logged ``carriage_air_m_s`` per sample, an
  omnidirectional hot-film anemometer on the carriage (its 3 g part of the slider's mass), put there to watch the
  air-conditioning's draught over the rig (2 % of its reading as noise, 0.01 m/s resolution). It reads the air's
  speed past it, ``U = sqrt((v - w)^2 + u_c^2)``, ``v`` the slider's speed, ``w`` the draught along the axis
  (positive toward +position) and ``u_c`` its part across the axis with the probe's own convection floor (drawn in
  0.04-0.08 m/s), through its first-order response ``tau_a`` (drawn in 30-80 ms) updated at each DAQ sample, ``y_k =
  y_(k-1) + (1 - exp(-(t_k - t_(k-1)) / tau_a)) (U_k - y_(k-1))``, from its settled reading at rest, ``y_0 = U_0``.
  The supply diffuser's swing louvre sweeps the draught on the session's clock, ``w = W cos(2 pi t / P + phi)``
  (``W`` drawn in 0.08-0.15 m/s, ``P`` in 25-50 s, ``phi`` uniform in 0-2 pi): the reading at rest moves from run to
  run with the louvre (0.05-0.16 m/s at seeds 1-3) and within a run follows ``|v - w|`` (up to 0.47 m/s against the
  draught; its correlation with the measured ``|speed|`` within a run about 0.8 in the median run, negative in a run
  that goes with the draught at about its speed); the louvre's sweep follows neither the plan nor the motor. The
  draught's force on the carriage (some 10 uN) and the probe's lead are left out: it acts on nothing and must not be
  traced.
* ``electrode_crack_asym`` -- no column; a change between runs at a run nobody logs, in one direction only. The drive
  feeds the stator's split electrodes (fired silver) from its two channels and swaps them for backward runs, so B2's
  coupling may differ between the directions (the model's ``asym_b``: B2 forced by ``d A_b (1 + d asym_b)``, 0 in
  the motor). The lead of one electrode is soldered near the plate's edge, where the drive's cyclic strain gathers:
  after run ``k_c`` (drawn among runs 14-30) a crack runs from the joint across the electrode and isolates a share
  ``c`` (drawn in 6-10 %) of it. From run ``k_c + 1`` on, the runs of that electrode's direction ``d_c`` (drawn
  among -1 and +1) force B2 with ``(1 - c) A_b``; the other direction's runs, and every run before, are the motor's
  own. A direction asymmetry that appears mid-session, in one direction's runs after ``k_c`` (22-27 runs of 72 at
  seeds 1-3, all backward): they slow by 3-13 % (the most against a load), and the plan's factors and the clock show
  nothing of it. The crack's share of L1's forcing and its change of the modes' phase are left out.
* ``stator_tc_swap`` -- logged ``stator_tc_C`` per sample, a fine thermocouple glued on the stator's face near its
  nodal line (0.05 K of noise, 0.01 degC resolution), whose bead is replaced mid-session: a cause logged through a
  sensor whose calibration shifts. A temperature study: the holder's pads are Peltier elements whose controller (on
  its own sensor in the pads) steps its set point every ``P`` (drawn in 15-25 s of the session's clock) to a new
  ``T_set_j`` (drawn uniform in 19-31 degC, to 0.1 degC), and the plate follows first order with ``tau_p`` (drawn in
  10-20 s; at the lab's 25 degC at the session's start): ``T(t) = T_set_j + (T(j P) - T_set_j) exp(-(t - j P) /
  tau_p)`` over ``j P <= t < (j + 1) P`` (22.0-27.1 / 20.7-27.6 / 23.6-28.6 degC over the sessions of seeds 1-3). Both
  modes move with it, ``f_b0 + c_b (T - 25 degC)`` and ``f_l0 + c_l (T - 25 degC)`` (``c_b`` drawn in -30..-20 Hz/K,
  ``c_l`` in -20..-10 Hz/K; the motor's own at 25 degC), held at their values at each run's start (a run moves ``T``
  by 0.15 K or less at seeds 1-3). After run ``k_s`` (drawn among runs 24-48) the operator finds the bead loose and
  glues a spare in the pause; the spare (a class 1 thermocouple) reads ``delta`` off (``|delta|`` drawn in 0.8-1.5 K,
  its sign at random): the logged reading is ``T + delta [run > k_s]`` plus the noise, the cause shifted by 16-45 Hz
  of B2 for the rest of the session. The drive (in its rack), the bar and the preload stay at the lab's temperature.

Sizes (measured on the made data: each TEST run's mean speed over its evaluation samples against the clean case's
same run, :func:`speed_change` (``bench/blind_effects_twentysixth.py``'s); its sd over the 16 TEST runs, and its
root mean square, at seeds 1 / 2 / 3, from the ``--data-only`` cases): ``preload_cell_crosstalk`` 3.46 / 3.83 / 3.15
% (4.02 / 3.84 / 3.46 %), ``electrode_crack_asym`` 3.77 / 2.97 / 2.61 % (4.51 / 3.29 / 3.26 %), ``stator_tc_swap``
2.28 / 2.33 / 3.22 % (2.45 / 3.27 / 3.40 %); the decoy's runs are the clean case's.

Pass rule (fixed before any loop ran; the eighth to twenty-seventh audits'): a kind passes when a regressor of
``WANT`` is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse
before and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``:
3.037 / 2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``carriage_air`` is nowhere in ``traced_all``
and ``a <= 1.02 b``. ``WANT``: for the preload, the load cell's column (a name holding ``preload_cell``: the reading
itself or a product, lag or shape of it the loop derives); for the thermocouple, its column (a name holding
``stator_tc``); for the crack, a regressor of the session's clock or the run count, or of a block, segment, regime,
change, jump, drift or trend of them, alone or with the direction (a name holding ``time``, ``session``, ``clock``,
``elapsed``, ``index``, ``count``, ``order``, ``block``, ``segment``, ``regime``, ``drift``, ``trend``, ``change``
or ``jump``), none holding ``time_in_run`` or ``in_run`` (the run's own clock), ``onset`` or ``start`` (the run's
start), ``break`` or ``pause`` (the plan's pauses are all alike), ``_lag``, ``prev`` or ``last`` (the runs'
conditions before), ``voltage``, ``load``, ``speed``, ``position`` or ``frequency`` (the crack follows none of the
plan's voltages and loads, nor the motion).

Usage: python bench/blind_effects_twentyeighth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND:
one of the above or clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST
free-run nrmse before and after, channels considered, CPU of the close loop by ``time.process_time``), plus
``traced_all`` (every traced regressor), ``want`` (the regressors accepted as the effect's) and
``accepted_in_first_two``.
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)
import blind_effects_fifth as b5  # noqa: E402
import blind_effects_twentysixth as b26  # noqa: E402

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics.stator import axial_force_N  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("preload_cell_crosstalk", "carriage_anemometer_decoy", "electrode_crack_asym", "stator_tc_swap")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"preload_cell_crosstalk": "preload_cell_N", "carriage_anemometer_decoy": "carriage_air_m_s",
           "electrode_crack_asym": None, "stator_tc_swap": "stator_tc_C"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"preload_cell_crosstalk": ("preload_cell",),
        "carriage_anemometer_decoy": (),
        "electrode_crack_asym": ("time", "session", "clock", "elapsed", "index", "count", "order", "block",
                                 "segment", "regime", "drift", "trend", "change", "jump"),
        "stator_tc_swap": ("stator_tc",)}
#: names that hold a word of ``WANT`` but are not accepted (for the crack the run's own clock, the run's start, the
#: plan's pauses, the runs' conditions before, the plan's voltage and load, the motion and the frequency)
NOT_WANT = {"electrode_crack_asym": ("time_in_run", "in_run", "onset", "start", "break", "pause", "_lag", "prev",
                                    "last", "voltage", "load", "speed", "position", "frequency")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"carriage_anemometer_decoy": "carriage_air"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
PRELOAD_SET_N = (5.0, 7.7)       # the preload the operator sets per run, uniform in this range [N]
CELL_NOISE_N = 0.005             # the load cell's noise [N]
AIR_NOISE = 0.02                 # the anemometer's relative noise
T_LAB_C = 25.0                   # the lab's temperature and the modes' reference [degC]
SETPOINT_C = (19.0, 31.0)        # the holder's set points, uniform in this range [degC]
N_SETPOINTS = 24                 # set points drawn per session (a session of 72 runs uses 4-7 of them)
TC_NOISE_K = 0.05                # the thermocouple's noise [K]


speed_change = b26.speed_change


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 301, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "preload_cell_crosstalk":
        return {"x": float(rng.uniform(0.015, 0.035)) * float(rng.choice([-1.0, 1.0])),
                "P_set_N": rng.uniform(*PRELOAD_SET_N, n_runs)}
    if kind == "carriage_anemometer_decoy":
        return {"W_m_s": float(rng.uniform(0.08, 0.15)), "P_s": float(rng.uniform(25.0, 50.0)),
                "phi": float(rng.uniform(0.0, 2.0 * math.pi)), "u_c_m_s": float(rng.uniform(0.04, 0.08)),
                "tau_a_s": float(rng.uniform(0.03, 0.08))}
    if kind == "electrode_crack_asym":
        return {"k_c": int(rng.integers(14, 31)), "c": float(rng.uniform(0.06, 0.10)),
                "d_c": int(rng.choice([-1, 1]))}
    if kind == "stator_tc_swap":
        return {"P_s": float(rng.uniform(15.0, 25.0)), "tau_p_s": float(rng.uniform(10.0, 20.0)),
                "c_b_Hz_K": float(rng.uniform(-30.0, -20.0)), "c_l_Hz_K": float(rng.uniform(-20.0, -10.0)),
                "k_s": int(rng.integers(24, 49)),
                "delta_K": float(rng.uniform(0.8, 1.5)) * float(rng.choice([-1.0, 1.0])),
                "T_set_C": np.round(rng.uniform(*SETPOINT_C, N_SETPOINTS), 1)}
    return {}


def preload_motor(mp, P_set_N: float, factor: float):
    """The run's motor with the preload the operator set, ``P_set_N``, times the run's contact factor ``factor``
    (the world's scatter of the preload kept as a factor of the set force)."""
    return mp.replace(stator__P0_N=P_set_N * factor)


def cell_reading_N(P_N, F_d_N, x: float):
    """The preload cell's reading [N]: the spring's force ``P_N`` plus its cross-talk ``x`` times the holder's
    tangential reaction to the drive force ``F_d_N``."""
    return np.asarray(P_N, float) + x * np.asarray(F_d_N, float)


def draught_m_s(t_s, p: dict):
    """The draught's component along the axis at the session's times ``t_s`` [m/s] (positive toward +position): the
    swing louvre's sweep, ``W cos(2 pi t / P + phi)``."""
    return p["W_m_s"] * np.cos(2.0 * math.pi * np.asarray(t_s, float) / p["P_s"] + p["phi"])


def air_speed_m_s(v_m_s, w_m_s, u_c_m_s: float):
    """The air's speed past the probe on the carriage [m/s]: ``sqrt((v - w)^2 + u_c^2)``."""
    return np.sqrt((np.asarray(v_m_s, float) - np.asarray(w_m_s, float)) ** 2 + u_c_m_s ** 2)


def probe_lag(t_s, U, tau_s: float) -> np.ndarray:
    """The probe's first-order response to ``U`` at the run's sample times ``t_s``, updated at each sample, ``y_k =
    y_(k-1) + (1 - exp(-(t_k - t_(k-1)) / tau)) (U_k - y_(k-1))``, from ``y_0 = U_0`` (settled at rest before the
    run)."""
    t, U = np.asarray(t_s, float), np.asarray(U, float)
    y = np.empty_like(U)
    y[0] = U[0]
    a = 1.0 - np.exp(-np.diff(t) / tau_s)
    for k in range(1, len(U)):
        y[k] = y[k - 1] + a[k - 1] * (U[k] - y[k - 1])
    return y


def crack_motor(mp, run: int, d: int, p: dict):
    """Run ``run``'s (1-based) motor in the direction ``d``: B2's coupling ``(1 - c) A_b`` in the cracked electrode's
    direction ``d_c`` after run ``k_c``, the motor's own otherwise."""
    if run > p["k_c"] and d == p["d_c"]:
        return mp.replace(stator__A_b_N_per_V=mp.stator.A_b_N_per_V * (1.0 - p["c"]))
    return mp


def plate_temp_C(t_s, p: dict) -> np.ndarray:
    """The stator's temperature [degC] at the session's times ``t_s >= 0``: from the lab's 25 degC at the session's
    start, first order with ``tau_p`` toward the holder's set point ``T_set[j]`` over ``j P <= t < (j + 1) P``."""
    t = np.asarray(t_s, float)
    P, tau, sp = p["P_s"], p["tau_p_s"], np.asarray(p["T_set_C"], float)
    at = np.empty(len(sp))  # the temperature at each set point's start
    x = T_LAB_C
    for j in range(len(sp)):
        at[j] = x
        x = sp[j] + (x - sp[j]) * math.exp(-P / tau)
    j = np.minimum(np.floor(t / P).astype(int), len(sp) - 1)
    return sp[j] + (at[j] - sp[j]) * np.exp(-(t - j * P) / tau)


def tc_motor(mp, T_C: float, p: dict):
    """The stator at ``T_C``: ``f_b0 + c_b (T - 25 degC)`` and ``f_l0 + c_l (T - 25 degC)`` (``c`` per kelvin)."""
    st = mp.stator
    return mp.replace(stator__f_b0_Hz=st.f_b0_Hz + p["c_b_Hz_K"] * (T_C - T_LAB_C),
                      stator__f_l0_Hz=st.f_l0_Hz + p["c_l_Hz_K"] * (T_C - T_LAB_C))


def tc_reading_C(T_C, run: int, p: dict):
    """The thermocouple's reading [degC] of the stator at ``T_C`` in run ``run`` (1-based): the spare's offset
    ``delta`` after run ``k_s``."""
    return np.asarray(T_C, float) + (p["delta_K"] if run > p["k_s"] else 0.0)


def run_motor(kind: str, mp, p: dict, k: int, d: int, factors, t_start: float = 0.0):
    """Run ``k``'s (0-based) motor of ``kind`` from its scattered motor ``mp`` (``d`` its direction, ``factors`` its
    contact factors, ``t_start`` its start on the session's clock [s])."""
    if kind == "preload_cell_crosstalk":
        return preload_motor(mp, float(p["P_set_N"][k]), float(factors[0]))
    if kind == "electrode_crack_asym":
        return crack_motor(mp, k + 1, d, p)
    if kind == "stator_tc_swap":
        return tc_motor(mp, float(plate_temp_C(t_start, p)), p)
    return mp


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next = [], [], 0.0
    record = b5.POSITION_AND_SPEED + ("Interface.F_d",)
    for k, (V, L, d) in enumerate(conds_run):
        mp = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, d, factors[k], t_next)
        r = b5.traverse(mp, nominal, plan, V, L, d, record=record)[0]
        idx = np.arange(0, len(r["time"]), every)
        t, s, v = r["time"][idx], r["Slider.s"][idx], r["Slider.v"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 302, k]).standard_normal(len(t))
        if kind == "preload_cell_crosstalk":
            P = axial_force_N(mp.stator, s)
            extra["preload_cell_N"] = np.round(cell_reading_N(P, r["Interface.F_d"][idx], p["x"])
                                               + CELL_NOISE_N * noise, 3)
        elif kind == "carriage_anemometer_decoy":
            U = air_speed_m_s(v, draught_m_s(t_next + t, p), p["u_c_m_s"])
            extra["carriage_air_m_s"] = np.round(probe_lag(t, U, p["tau_a_s"]) * (1.0 + AIR_NOISE * noise), 2)
        elif kind == "stator_tc_swap":
            T = plate_temp_C(t_next + t, p)
            extra["stator_tc_C"] = np.round(tc_reading_C(T, k + 1, p) + TC_NOISE_K * noise, 2)
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        duration = float(r["time"][-1])
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p, "f_l0_Hz": mp.stator.f_l0_Hz,
                        "f_b0_Hz": mp.stator.f_b0_Hz, "A_b_N_per_V": mp.stator.A_b_N_per_V,
                        "t_start_s": t_next, "duration_s": duration})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def accepted(kind: str, name: str) -> bool:
    """Whether the traced regressor ``name`` is the kind's: a word of ``WANT`` and none of ``NOT_WANT``."""
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
