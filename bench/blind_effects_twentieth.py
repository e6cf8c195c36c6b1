#!/usr/bin/env python
"""A twentieth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the nineteen earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_nineteenth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame, printed row and
``run_audit``): the realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at
a 1 ms step, 1 mm/s speed noise, 2 % run-to-run contact scatter). The dither's force on the slider uses the fifth
audit's state-dependent input (``bench/blind_effects_fifth.py``: an FMU input computed each step from the slider's
position and speed of the step before). Each kind draws from one random stream of its seed. The kinds:

* ``lining_grit_ploughing`` -- no column; a change between runs by random events. The composite lining sheds hard
  wear particles (filler grains) as the tip slides over it, at a rate ``lam`` per metre of the tip's sliding (drawn
  in 3.0-5.0 /m: a session slides some 3.1-3.2 m), so the number shed during run ``k`` is Poisson with the mean ``lam
  dS_k`` (``dS_k = 0.2 m/s x V0 / 324 V x`` the run's duration, the tip's sliding). A particle shed in run ``k``
  is dragged into the contact for run ``k + 1`` and ploughs the lining there: a ploughing term (Bowden and Tabor's
  adhesion plus ploughing) adds a share ``c_j`` of the slip friction (drawn per particle in 6-12 %). The tip grinds
  and sweeps it out as it slides, first order in the sliding distance: ``mu_p (1 + sum_j c_j exp(-(S_k - S_j) /
  S_g))`` with ``S_k`` the tip's sliding distance at run ``k``'s start, ``S_j`` at the start of the run the particle
  entered, and ``S_g`` drawn in 0.03-0.06 m (a particle lasts one or two runs). The co-simulation holds ``mu_p`` per
  run: the share at the run's start. Its timing follows the runs' own sliding (V0 and the duration) and chance; no
  column, no rest and no protocol step marks it.
* ``lining_grit_logged`` -- the grit's control, not a kind of its own: the same draw and the same motion as
  ``lining_grit_ploughing`` at the seed, with the ploughing share logged as ``grit_plough_pct`` (100 times the sum,
  per sample, 0.01 %-point resolution, no noise), as an in-situ contact microscope's particle count turned into a
  ploughing share by the lab's calibration would read it. What the loop makes of the state logged tells the hidden
  grit's loss.
* ``guide_ultrasonic_dither`` -- logged ``rail_dither_um`` per sample, a laser vibrometer's reading of the
  ultrasonic vibration amplitude between the guide's rail and the carriage along the motion (0.005 um of noise,
  0.001 um resolution). A friction-reduction study: a Langevin transducer bolted to the guide's base rail vibrates
  it along the axis at its resonance ``f_u`` (drawn in 20-28 kHz), with an amplitude ``a`` the operator sets per
  run (uniform in 0-1.5 um). A tangential vibration of velocity amplitude ``V_d = 2 pi f_u a`` reverses the
  rollers' sliding for part of each cycle when the slider is slower than it, so the mean Coulomb friction of the
  rollers it reaches falls (Littmann, Storck and Wallaschek's law): ``(2 / pi) arcsin(|v| / V_d)`` of its level for
  ``|v| < V_d``, its own level for ``|v| >= V_d`` (``v`` the slider's speed). The vibration reaches the rollers on
  the driven rail's side, a share ``x`` of the guide's friction (drawn in 0.3-0.5; the carriage partly follows the
  rail), so the guide's friction is ``mu_sd N (1 - x + x (2 / pi) arcsin(min(1, |v| / V_d)))`` (``N = kappa F_p(s)
  + g m_s`` the guide's normal load). Set through the slider's load input as the force ``sign(v) x mu_sd N (1 -
  (2 / pi) arcsin(min(1, |v| / V_d)))`` that gives back the friction the vibration takes away (the load's inertia
  moved into the slider's mass and the guide's Coulomb levels and preload share rescaled,
  :func:`blind_effects.load_in_slider_motor`: the moving mass and the guide's friction are the motor's). The static
  level at rest is left as the motor's (the slider leaves its stop once the drive beats it). A law of the logged
  amplitude times a falling function of the slider's speed: it acts most on the slow runs and at each run's start.
* ``match_cap_curie_weiss`` -- logged ``match_cap_temp_C`` per sample, a thermocouple on the drive's matching
  capacitor (0.05 degC of noise, 0.01 degC resolution). A drive-qualification study: the drive's board sits in a
  small temperature chamber set per run (uniform in 18-40 degC); the tank's inductor is a separate coil on the
  motor's base, at the lab's 25 degC with the motor. The 3.0 nF matching capacitor ``C1`` was made up of a stable
  C0G part and a high-permittivity (Y5V-class, barium titanate) part of share ``y`` of it at 25 degC (``y`` drawn in
  0.15-0.25), whose dielectric is paraelectric above its Curie point and follows the Curie-Weiss law, ``eps ~ 1 / (T -
  theta)`` (``theta`` drawn in 0-10 degC): ``C1(T) = C1 (1 - y + y (25 - theta) / (T - theta))``. The operator's
  supply table is for the capacitor at 25 degC and ``voltage_V`` logs the plan's V0: the tank's gain, and with it
  the stator's amplitude, follows the capacitor's temperature (a hyperbola, steeper at the cold end).
* ``weight_sway_decoy`` -- a decoy, no effect on the motor: logged ``weight_sway_mm`` per sample, the sway amplitude
  of the hanging weight as a camera beside it reads it (the envelope of its swing, 0.02 mm of noise, 0.01 mm
  resolution, read as ``max(0, .)``). Each time the operator hangs a new weight (the first run and every run whose
  load differs from the run before's; the weight hung at the start of the pause before that run) the hand leaves
  it swinging with an amplitude ``A_h`` (drawn per hanging in 2-8 mm) that the air's drag damps, ``A_h exp(-(t -
  t_h) / tau)`` (``tau`` drawn in 30-90 s, ``t_h`` the hanging's time on the session clock); a run without a load
  hangs no weight and reads 0. It follows the plan's load changes and the session clock since them; a swing of a few
  mm on a 0.3 m cable changes the cable's pull by parts in 10^4 (left out), so it acts on nothing and must not be
  traced.

Pass rule (fixed before any loop ran; the eighth to nineteenth audits'): a kind passes when a regressor of ``WANT``
is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before
and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``: 3.037 /
2.815 / 3.241 % at seeds 1 / 2 / 3). The decoy passes when ``weight_sway`` is nowhere in ``traced_all`` and ``a <=
1.02 b``. ``WANT``: the vibrometer's column for the dither (a name holding ``dither``); the capacitor's thermocouple
for the capacitor (a name holding ``cap_temp``); for the grit, a regressor of the state (a name holding ``grit``,
``plough``, ``debris`` or ``particle``) or of short stretches of the session (a name holding ``block``), none
holding ``load`` or ``voltage``. The control is reported with its own column (``grit_plough_pct``) but not counted.

Usage: python bench/blind_effects_twentieth.py KIND SEED [--cache DIR] [--data-only] [--report FILE]   (KIND: one of
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
import blind_effects_fifth as b5  # noqa: E402

from l1b2.cosim.engine import InProcessMotor  # noqa: E402
from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics import driver as drv  # noqa: E402
from l1b2.physics.slider import G_M_S2  # noqa: E402
from l1b2.physics.stator import preload_N  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("lining_grit_ploughing", "guide_ultrasonic_dither", "match_cap_curie_weiss", "weight_sway_decoy",
         "lining_grit_logged")
#: a kind that draws from another kind's stream (the same draw)
STREAM = {"lining_grit_logged": "lining_grit_ploughing"}
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"lining_grit_ploughing": None, "guide_ultrasonic_dither": "rail_dither_um",
           "match_cap_curie_weiss": "match_cap_temp_C", "weight_sway_decoy": "weight_sway_mm",
           "lining_grit_logged": "grit_plough_pct"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"lining_grit_ploughing": ("grit", "plough", "debris", "particle", "block"),
        "guide_ultrasonic_dither": ("dither",),
        "match_cap_curie_weiss": ("cap_temp",),
        "weight_sway_decoy": (),
        "lining_grit_logged": ("grit_plough",)}
#: names that hold a word of ``WANT`` but are not accepted (the plan's inputs)
NOT_WANT = {"lining_grit_ploughing": ("load", "voltage")}
#: the decoy's column: it passes only when nowhere in ``traced_all``
DECOY = {"weight_sway_decoy": "weight_sway"}
#: the clean control's TEST free-run nrmse before the loop [%] at seeds 1, 2, 3 (``bench/blind_effects.py clean``)
B0 = {1: 3.037, 2: 2.815, 3: 3.241}
TIP_SPEED_M_S = 0.2          # the tip's sliding speed at 324 V (as bench/blind_effects.py)
A_MAX_UM = 1.5               # the dither's largest amplitude set [um]
CAP_T_RANGE = (18.0, 40.0)   # the drive chamber's set point per run [degC]
T_REF = 25.0                 # the lab's temperature: the capacitor's nominal value
SWAY_FLOOR_MM = 0.0          # the camera reads no negative amplitude


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``; the control the grit's)."""
    src = STREAM.get(kind, kind)
    rng = np.random.default_rng([seed, 221, KINDS.index(src) if src in KINDS else 99])
    if src == "lining_grit_ploughing":
        # the Poisson counts and the particles' shares are drawn from the same stream as the run goes
        return {"lam_per_m": float(rng.uniform(3.0, 5.0)), "S_g_m": float(rng.uniform(0.03, 0.06)),
                "u_count": rng.uniform(0.0, 1.0, n_runs), "c_pool": rng.uniform(0.06, 0.12, 4 * n_runs)}
    if kind == "guide_ultrasonic_dither":
        return {"f_u_Hz": float(rng.uniform(20e3, 28e3)), "x_share": float(rng.uniform(0.3, 0.5)),
                "a_um": rng.uniform(0.0, A_MAX_UM, n_runs)}
    if kind == "match_cap_curie_weiss":
        return {"y": float(rng.uniform(0.15, 0.25)), "theta_C": float(rng.uniform(0.0, 10.0)),
                "T": rng.uniform(*CAP_T_RANGE, n_runs)}
    if kind == "weight_sway_decoy":
        return {"tau_s": float(rng.uniform(30.0, 90.0)), "A_h_mm": rng.uniform(2.0, 8.0, n_runs)}
    return {}


def poisson_count(u: float, mean: float) -> int:
    """The Poisson count of mean ``mean`` at the uniform ``u`` (the inverse of its distribution function)."""
    k, pk = 0, math.exp(-mean)
    cdf = pk
    while u > cdf and k < 100:
        k += 1
        pk *= mean / k
        cdf += pk
    return k


def sliding_m(V0: float, duration_s: float) -> float:
    """The tip's sliding distance [m] over a run: ``0.2 m/s x V0 / 324 V x duration``."""
    return TIP_SPEED_M_S * float(V0) / 324.0 * float(duration_s)


def plough_share(S: float, entries, S_g: float) -> float:
    """The particles' ploughing share at the sliding distance ``S``: ``sum c_j exp(-(S - S_j) / S_g)`` over the
    ``entries`` ``(S_j, c_j)``."""
    return float(sum(c * math.exp(-(S - S_j) / S_g) for S_j, c in entries))


def dither_speed_m_s(a_um: float, f_u: float) -> float:
    """The dither's velocity amplitude [m/s] ``2 pi f_u a`` (``a`` in um)."""
    return 2.0 * math.pi * f_u * a_um * 1e-6


def littmann_share(v, V_d: float):
    """The guide's mean Coulomb friction under the dither, a share of the motor's: ``(2 / pi) arcsin(|v| / V_d)``
    for ``|v| < V_d``, 1 otherwise (1 without a dither, ``V_d = 0``)."""
    v = np.abs(np.asarray(v, float))
    if V_d <= 0:
        return np.ones_like(v)
    return np.where(v < V_d, (2.0 / math.pi) * np.arcsin(np.minimum(v / V_d, 1.0)), 1.0)


def dither_force_N(s: float, v: float, mp, V_d: float, x: float) -> float:
    """The force [N] along the motion that gives back what the dither takes from the share ``x`` of the guide's
    friction of the motor ``mp`` it reaches: ``sign(v) x mu_sd (kappa F_p(s) + g m_s) (1 - share)``; 0 at rest."""
    if v == 0.0 or V_d <= 0:
        return 0.0
    sl = mp.slider
    N = sl.kappa * float(preload_N(mp.stator, float(s))) + G_M_S2 * sl.mass_kg
    return math.copysign(1.0, v) * x * sl.mu_sd * N * (1.0 - float(littmann_share(v, V_d)))


def cap_factor(T, y: float, theta: float):
    """The matching capacitor's share of its 25 degC value: ``1 - y + y (25 - theta) / (T - theta)``."""
    return 1.0 - y + y * (T_REF - theta) / (np.asarray(T, float) - theta)


def sway_mm(t, t_h: float, A_h: float, tau: float):
    """The weight's sway amplitude [mm] at the session times ``t`` (no noise, no rounding): ``A_h exp(-(t - t_h) /
    tau)``."""
    return A_h * np.exp(-(np.asarray(t, float) - t_h) / tau)


def run_motor(kind: str, mp, p: dict, k: int, L: float, share: float = 0.0):
    """Run ``k``'s motor of ``kind`` from its scattered motor ``mp`` (``L`` the run's load, ``share`` the grit's
    ploughing share), and its load law (None: the run's load)."""
    if STREAM.get(kind, kind) == "lining_grit_ploughing":
        return mp.replace(interface__mu_p=mp.interface.mu_p * (1.0 + share)), None
    if kind == "guide_ultrasonic_dither":
        V_d, x = dither_speed_m_s(float(p["a_um"][k]), p["f_u_Hz"]), p["x_share"]
        own = mp
        return (be.load_in_slider_motor(mp, L, kind),
                lambda t, s, v: L - dither_force_N(s, v, own, V_d, x) / G_M_S2)
    if kind == "match_cap_curie_weiss":
        return mp.replace(driver__C1_F=mp.driver.C1_F * float(cap_factor(p["T"][k], p["y"], p["theta_C"]))), None
    return mp, None


def traverse(mp, nominal, plan, V0, load, d, load_law=None):
    """One traverse (as :func:`blind_effects.traverse`) with the load input given as a law of the slider's state
    (None: the run's load); the operator's supply is set from the nominal drive at 25 degC and f0."""
    if load_law is None:
        return be.traverse(mp, nominal, plan, V0, load, d)
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    l_in = b5.StateInput(load_law, s0)
    m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=d, m_load=l_in, s0=s0)
    l_in.motor = m
    return m.run(plan.max_run_s, record=("Slider.s",), until=lambda mm: mm.value("Slider.at_stop") == d)


def experiment(kind: str, seed: int, first: int | None = None):
    """The 72-run experiment of one kind and its truth (``first``: only the first runs, the same draws)."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    grit = STREAM.get(kind, kind) == "lining_grit_ploughing"
    conds_run = conds[:first] if first else conds
    frames, per_run, t_next = [], [], 0.0
    S, entries, n_c = 0.0, [], 0           # the tip's sliding so far, the particles (S_j, c_j), shares used
    t_h, A_h, L_prev = None, 0.0, None     # the weight's hanging time and amplitude, the run before's load
    for k, (V, L, d) in enumerate(conds_run):
        share = plough_share(S, entries, p["S_g_m"]) if grit else 0.0
        mp, load_law = run_motor(kind, scattered_motor(nominal, factors[k]), p, k, L, share)
        r = traverse(mp, nominal, plan, V, L, d, load_law)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        dur = float(r["time"][-1])
        if L_prev is None or L != L_prev:  # a new weight hung at the start of the pause before this run
            t_h, A_h = t_next - plan.pause_s, float(p["A_h_mm"][k]) if kind == "weight_sway_decoy" else 0.0
        extra = {}
        noise = np.random.default_rng([seed, 222, k]).standard_normal(len(t))
        if kind == "guide_ultrasonic_dither":
            extra["rail_dither_um"] = np.round(p["a_um"][k] + 0.005 * noise, 3)
        elif kind == "match_cap_curie_weiss":
            extra["match_cap_temp_C"] = np.round(p["T"][k] + 0.05 * noise, 2)
        elif kind == "weight_sway_decoy":
            clean = sway_mm(t_next + t, t_h, A_h, p["tau_s"]) if L != 0 else np.zeros(len(t))
            extra["weight_sway_mm"] = np.round(np.maximum(clean + 0.02 * noise, SWAY_FLOOR_MM), 2)
        elif kind == "lining_grit_logged":
            extra["grit_plough_pct"] = np.full(len(t), round(100.0 * share, 2))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, None, **extra)
        frames.append(out)
        dS = sliding_m(V, dur)
        n_new = 0
        if grit:  # particles shed in this run enter the contact for the next one
            n_new = poisson_count(float(p["u_count"][k]), p["lam_per_m"] * dS)
            for _ in range(n_new):
                entries.append((S + dS, float(p["c_pool"][n_c])))
                n_c += 1
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p, "mu_sd": mp.slider.mu_sd,
                        "C1_F": mp.driver.C1_F, "plough_share": share, "S_m": S, "shed": n_new,
                        "t_start_s": t_next, "duration_s": dur, "t_hung_s": t_h})
        S += dS
        L_prev = L
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
