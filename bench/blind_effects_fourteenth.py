#!/usr/bin/env python
"""A fourteenth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the thirteen earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_thirteenth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``oil_dose_film`` -- logged ``oil_dose_nL`` per sample, the dose a metering micro-dispenser puts on the friction
  bar's track before each run (a lubrication study: the dose is a design factor, uniform in 1-6 nL per run; the
  dispenser's flow sensor reads it with 0.05 nL of noise per sample, 0.01 nL resolution). A felt wiper first levels
  the track to a residual film ``h_r`` (drawn in 40-60 nm), then spreads the dose over the track (3 mm x 50 mm, so
  ``1 nL`` adds ``6.67 nm``): the film is ``h = h_r + V / A``. The film is thinner than the lining's roughness, so the
  asperities still carry the tip's load (its Coulomb slip friction is left as it is), but the film fills the gap
  between them and shears with the slip: a Couette shear, whose viscous slip coefficient falls as the film's
  inverse, ``sigma(V) = sigma (h_r + V_ref / A) / (h_r + V / A)`` with ``V_ref`` = 3.5 nL the lab's usual dose (the
  motor's own ``sigma``): a hyperbolic law of the logged dose (about 1.3 sigma at 1 nL down to 0.8 sigma at 6 nL).
* ``operator_hook_handover`` -- no column; a change of the operator between runs. After run k (the k-th, 1-based,
  drawn in 20-52) a second operator takes over the session after a handover's rest (drawn in 60-240 s before run
  k + 1). The second operator hangs the weights from an S-hook of their own, heavier than the rig's hook by ``m_h``
  (drawn in 6-12 g); the plan's loads (which the DAQ logs) count the rig's hook. So from run k + 1 on every loaded
  run carries ``m_h`` more on the same side (``load + sign(load) m_h``: force and inertia); a run without a load
  hangs no hook at all and is unchanged.
* ``handover_rest_control`` -- the handover's control, not a kind of its own: the same draw (the same rest before
  the same run), the second operator using the rig's hook. It tells what the rest alone does to the loop.
* ``shared_lead_droop`` -- logged ``stage_heater_A`` per sample: the current of a neighbouring experiment's Peltier
  stage, read by a clamp meter (0.02 A of noise, 0.01 A resolution). Through the drive's supply, by a common
  impedance: the stage hangs on the same bench supply as the drive, behind the same pair of thin leads to the
  bench's distribution strip (their resistance ``R`` drawn in 0.4-0.7 Ohm); the supply regulates at its terminals.
  The stage's controller steps its current on its own program on the session clock: a new level (uniform 0-8 A)
  after intervals exponential with a mean ``T_i`` (drawn in 2-5 s), so it may step within a run. The drive takes
  the bus current ``V_b / R_eq`` (its tank's real power ``V0^2 / (2 R_m)`` at ``V0 = G V_b``: ``R_eq = 2 R_m / G^2``,
  about 171 Ohm), so the drive's bus is ``V_b = (V_set - R I) / (1 + R / R_eq)`` (``V_set`` the operator's setting
  for the plan's V0; V0 follows the bus): a loss ``R I / V_set`` relative to the setting, larger at the lower V0
  (up to 5.6 V: 12 % of V0 at 220 V, 8 % at 324 V). ``voltage_V`` logs the plan's V0.
* ``pad_creep_decoy`` -- a decoy, no effect on the motor: logged ``board_sink_um`` per sample, a capacitive gauge
  under the breadboard's -position end (0.05 um of noise, 0.01 um resolution). The breadboard stands on sorbothane
  pads; the hanging weights pull on its end pulleys (a positive load at the -position end, a negative one at the
  +position end), and the board pivots on its pads, sinking at the gauge's end by a viscoelastic creep of the
  signed load's weight: a standard linear solid, ``c g (s_i m + (1 - s_i) y)`` with ``y`` the load's first-order lag
  on the session clock (time constant ``tau`` drawn in 10-30 s, from 0 before the first run; each run's weight
  hangs from the end of the run before), ``c`` drawn in 2-4 um/N and the instantaneous share ``s_i`` in 0.2-0.4,
  less the pads' settling ``d_s (1 - exp(-t / 300 s))`` (``d_s`` drawn in 1-3 um). It follows the signed load and
  its history over the last runs (a lag of the settings), not the motion; a tilt of micro-radians acts on nothing
  and it must not be traced.

Pass rule (fixed before any loop ran; the eighth to thirteenth audits'): a kind passes when a regressor of ``WANT``
is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before
and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``board_sink_um`` is nowhere in ``traced_all`` and ``a <=
1.02 b``. ``WANT``: the dispenser's column for the oil (a name holding ``oil_dose``); the stage's current for the
droop (a name holding ``stage_heater``; the voltage alone is not accepted: the logged V0 is the setting, the loss
follows the neighbour); for the handover, a regressor of the session's clock or order or of the rests between runs
(its name holds ``time``, ``order``, ``index``, ``count``, ``since``, ``session``, ``pause``, ``rest``, ``gap``,
``segment`` or ``break``, and not ``time_in_run``: the run's own clock carries no change between runs; the load
alone is not accepted: the logged load is right before the handover). The control has no pass rule (``WANT``
empty; it is reported, not judged).

Usage: python bench/blind_effects_fourteenth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
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

KINDS = ("oil_dose_film", "operator_hook_handover", "shared_lead_droop", "pad_creep_decoy", "handover_rest_control")
#: a kind that draws from another kind's stream (the same draw, no effect)
STREAM = {"handover_rest_control": "operator_hook_handover"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"oil_dose_film": "oil_dose_nL", "operator_hook_handover": None, "shared_lead_droop": "stage_heater_A",
           "pad_creep_decoy": "board_sink_um", "handover_rest_control": None}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"oil_dose_film": ("oil_dose",),
        "operator_hook_handover": ("time", "order", "index", "count", "since", "session", "pause", "rest", "gap",
                                   "segment", "break"),
        "shared_lead_droop": ("stage_heater",),
        "pad_creep_decoy": (),
        "handover_rest_control": ()}
#: names that hold a word of ``WANT`` but are not accepted (the run's own clock)
NOT_WANT = {"operator_hook_handover": ("time_in_run",)}
G_N_PER_KG = 9.81           # the weights' g
TRACK_M2 = 3e-3 * 50e-3     # the bar's track the dose spreads over [m^2]
V_REF_NL = 3.5              # the lab's usual dose [nL], at which the motor's own sigma holds
SETTLE_S = 300.0            # the pads' settling time constant [s]


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the handover's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 161, KINDS.index(src) if src in KINDS else 99])
    if kind == "oil_dose_film":
        return {"h_r_nm": float(rng.uniform(40.0, 60.0)), "dose_nL": rng.uniform(1.0, 6.0, n_runs)}
    if src == "operator_hook_handover":
        p = {"k_hand": int(rng.integers(20, 53)), "m_h_kg": float(rng.uniform(0.006, 0.012)),
             "rest_s": float(rng.uniform(60.0, 240.0))}
        if kind == "handover_rest_control":
            p["m_h_kg"] = 0.0
        return p
    if kind == "shared_lead_droop":
        R, T_i = float(rng.uniform(0.4, 0.7)), float(rng.uniform(2.0, 5.0))
        steps = np.cumsum(rng.exponential(T_i, 2000))     # far past any session's end
        return {"R_ohm": R, "T_i_s": T_i, "step_s": steps, "level_A": rng.uniform(0.0, 8.0, steps.size + 1)}
    if kind == "pad_creep_decoy":
        return {"c_um_per_N": float(rng.uniform(2.0, 4.0)), "s_i": float(rng.uniform(0.2, 0.4)),
                "tau_s": float(rng.uniform(10.0, 30.0)), "d_s_um": float(rng.uniform(1.0, 3.0))}
    return {}


def film_sigma_factor(dose_nL, h_r_nm: float):
    """The viscous slip coefficient's factor at the dose ``dose_nL``: ``(h_r + V_ref / A) / (h_r + V / A)``."""
    nm_per_nL = 1e-12 / TRACK_M2 * 1e9
    return (h_r_nm + V_REF_NL * nm_per_nL) / (h_r_nm + np.asarray(dose_nL, float) * nm_per_nL)


def load_of_run(p: dict, k: int, load_kg: float) -> float:
    """The load [kg] run ``k`` (0-based) carries: the plan's, plus the second operator's extra hook ``m_h`` on the
    load's side from the run after the handover's run ``k_hand`` (1-based) on; a run without a load is unchanged."""
    if "k_hand" in p and k >= p["k_hand"] and load_kg != 0.0:
        return float(load_kg + np.sign(load_kg) * p["m_h_kg"])
    return float(load_kg)


def rest_before(p: dict, k: int, pause_s: float) -> float:
    """The rest [s] before run ``k`` (0-based): the handover's before the second operator's first run, the plan's
    pause otherwise."""
    return float(p["rest_s"]) if "k_hand" in p and k == p["k_hand"] else float(pause_s)


def heater_A(t_s, step_s, level_A):
    """The stage's current [A] at the session times ``t_s``: ``level_A[i]`` between ``step_s[i-1]`` and
    ``step_s[i]`` (``level_A[0]`` before the first step)."""
    return np.asarray(level_A, float)[np.searchsorted(np.asarray(step_s, float), np.asarray(t_s, float),
                                                      side="right")]


def drive_gain(nominal, plan) -> float:
    """``G = V0 / V_bus`` of the nominal drive at the plan's frequency and ambient."""
    return 1.0 / float(drv.supply_for_voltage_V(nominal.driver, 1.0, 1.0, plan.f_drive_Hz, plan.ambient_degC))


def bus_V(V_set, I_A, R_ohm: float, R_eq_ohm: float):
    """The drive's bus [V] behind the shared leads: ``(V_set - R I) / (1 + R / R_eq)``."""
    return (np.asarray(V_set, float) - R_ohm * np.asarray(I_A, float)) / (1.0 + R_ohm / R_eq_ohm)


def creep_lag(t_s, m_kg: float, y0: float, t0_s: float, tau_s: float):
    """The load's first-order lag at the session times ``t_s`` under the constant load ``m_kg`` from ``t0_s`` on,
    from ``y0`` at ``t0_s``: ``m + (y0 - m) exp(-(t - t0) / tau)``."""
    return m_kg + (y0 - m_kg) * np.exp(-(np.asarray(t_s, float) - t0_s) / tau_s)


def board_sink_um(t_s, m_kg: float, y, p: dict):
    """The gauge's reading [um] (no noise, no rounding) at the session times ``t_s`` with the hanging load ``m_kg``
    and its lag ``y``: ``c g (s_i m + (1 - s_i) y) - d_s (1 - exp(-t / 300 s))``."""
    t = np.asarray(t_s, float)
    return (p["c_um_per_N"] * G_N_PER_KG * (p["s_i"] * m_kg + (1.0 - p["s_i"]) * np.asarray(y, float))
            - p["d_s_um"] * (1.0 - np.exp(-t / SETTLE_S)))


def traverse(mp, nominal, plan, V0, load, d, V_s=None):
    """One traverse at the plan's frequency with the supply ``V_s`` (a number or a function of the run's time;
    default: the operator's setting for ``V0`` from the nominal drive at 25 degC)."""
    if V_s is None:
        V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=d, m_load=load, s0=s0)
    return m.run(plan.max_run_s, record=("Slider.s", "Slider.v"),
                 until=lambda mm: mm.value("Slider.at_stop") == d)


def run_setup(kind: str, mp, nominal, plan, p: dict, k: int, V0: float, L: float, t_start_s: float):
    """``(motor, load, V_s)`` of run ``k`` of ``kind`` from its scattered motor ``mp``, starting at the session time
    ``t_start_s`` (``V_s`` None: the operator's setting; else a function of the run's time)."""
    if kind == "oil_dose_film":
        fac = float(film_sigma_factor(p["dose_nL"][k], p["h_r_nm"]))
        return mp.replace(interface__sigma_N_s_per_m=mp.interface.sigma_N_s_per_m * fac), L, None
    if kind in ("operator_hook_handover", "handover_rest_control"):
        return mp, load_of_run(p, k, L), None
    if kind == "shared_lead_droop":
        V_set = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
        G = drive_gain(nominal, plan)
        R_eq = 2.0 * nominal.driver.R_m_ohm / G ** 2
        R, steps, levels = p["R_ohm"], p["step_s"], p["level_A"]
        return mp, L, lambda t: float(bus_V(V_set, heater_A(t_start_s + t, steps, levels), R, R_eq))
    return mp, L, None


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next = [], [], 0.0
    y, t_y = 0.0, -plan.pause_s          # the decoy's lag, and the time it was taken at
    for k, (V, L, d) in enumerate(conds):
        if k > 0:
            t_next += rest_before(p, k, plan.pause_s) - plan.pause_s
        mp, load, V_s = run_setup(kind, scattered_motor(nominal, factors[k]), nominal, plan, p, k, V, L, t_next)
        r = traverse(mp, nominal, plan, V, load, d, V_s)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 162, k]).standard_normal(len(t))
        if kind == "oil_dose_film":
            extra["oil_dose_nL"] = np.round(p["dose_nL"][k] + 0.05 * noise, 2)
        elif kind == "shared_lead_droop":
            extra["stage_heater_A"] = np.round(heater_A(t_next + t, p["step_s"], p["level_A"]) + 0.02 * noise, 2)
        elif kind == "pad_creep_decoy":
            ys = creep_lag(t_next + t, L, y, t_y, p["tau_s"])
            extra["board_sink_um"] = np.round(board_sink_um(t_next + t, L, ys, p) + 0.05 * noise, 2)
            y, t_y = float(ys[-1]), float(t_next + t[-1])
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "sigma": mp.interface.sigma_N_s_per_m, "load_kg": load, "t_start_s": t_next,
                        "duration_s": float(r["time"][-1]),
                        "V_bus_mean": None if V_s is None else float(np.mean([V_s(x) for x in t]))})
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    if kind == "shared_lead_droop":      # keep the truth's file small: the steps up to the session's end
        n = int(np.searchsorted(p["step_s"], t_next)) + 1
        p = dict(p, step_s=p["step_s"][:n], level_A=p["level_A"][:n + 1])
    return be.finish(kind, frames, per_run, p, nominal, plan)


def accepted(kind: str, name: str) -> bool:
    """Whether the traced regressor ``name`` is the kind's (a word of ``WANT`` and none of ``NOT_WANT``)."""
    return be.accepted_by(WANT, NOT_WANT, kind, name)


def main(argv=None):
    be.run_audit(argv, __doc__, KINDS, experiment, CHANNEL, WANT, NOT_WANT)


if __name__ == "__main__":
    main()
