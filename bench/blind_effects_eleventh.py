#!/usr/bin/env python
"""An eleventh blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the ten earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_tenth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). The elastic load line uses the fifth audit's state-dependent input
(``bench/blind_effects_fifth.py``: an FMU input computed each step from the slider's position and speed of the step
before). Each kind draws from one random stream of its seed. The kinds:

* ``clamp_torque_damping`` -- logged ``clamp_torque_cNm`` per sample, a reaction-torque sensor under the head of the
  stator holder's clamping screw (0.2 cN m of noise, 0.1 cN m resolution). The clamping torque is a factor of the
  design, set per run with a torque screwdriver (uniform 20-70 cN m). The holder's pads grip the plate at its
  centre, where the L1 mode's axial strain is largest; the pads' joint microslips there each cycle and dissipates
  part of L1's energy. As the clamp tightens, the joint's slip zone shrinks toward full stick and its damping falls
  toward the material's own floor, ``zeta_l(tau) = zeta_l (1 - s + s exp(-(tau - 30 cN m) / tau0))`` (``s`` drawn in
  0.25-0.35, the joint's share of L1's damping at the reference 30 cN m; ``tau0`` in 8-14 cN m): monotone,
  decreasing, saturating at the floor ``zeta_l (1 - s)`` for a tight clamp and up to ~1.5 zeta_l for a loose one.
  B2 bends in the plate's plane, which the pads on its thickness faces barely hold: left as it is.
* ``film_carryover`` -- no column; a memory between runs tied to the previous run's condition. The friction bar is
  lightly oiled (the realistic motor's lubricated bar). Each pass of the bar under the tip wipes the film and leaves
  behind it a film whose thickness follows hydrodynamic entrainment (Landau-Levich-Derjaguin), ``h ~ v^(2/3)``, v the
  speed at which the bar passes the contact: the slider's speed. The next run meets the film the previous one left
  (the 1 s pause is short against the film's levelling), and a thicker film carries more of the tip's load,
  lowering the boundary (Coulomb) slip friction: ``mu_p (1 - B ((v_prev / 0.2 m/s)^(2/3) - 1))``, ``v_prev`` the
  previous run's mean speed (its stroke over its duration; the operator's warm-up pass before the first run is taken
  at 0.2 m/s), ``B`` drawn in 0.15-0.25. A backward run meets its own condition's film; a forward run meets the
  previous condition's, at another V0 and load.
* ``elastic_load_line`` -- no column; in time within a run, with the load. The weight hangs on a nylon thread over
  the pulley; the paper's model takes the load as a rigid mass moving with the slider. The thread's stiffness is
  ``k`` (drawn in 200-500 N/m: 0.3 mm nylon, ~0.4 m from slider to weight) and its internal loss factor ``eta``
  (drawn in 0.04-0.10, taken as a viscous ``c = eta k / omega_n``, ``omega_n = sqrt(k / |m|)``). With ``q`` the
  slider's travel toward the load's pulley and ``z`` the weight's descent from the start (both 0 at rest, the thread
  stretched by ``|m| g / k``), the thread's tension is ``T = max(0, |m| g + k (z - q) + c (dz/dt - dq/dt))`` (a thread
  goes slack, it does not push) and the weight obeys ``|m| d2z/dt2 = |m| g - T``. The slider feels ``T`` toward the
  pulley (set through its load input as ``sign(m) T / g`` with ``load_inertia`` 0: the weight's inertia is in the
  thread's model, not the slider's). At each run's start the slider leaves the weight behind, then the weight
  follows through the thread: a ringing at 7.5-21 Hz (``sqrt(k / |m|) / 2 pi`` over the plan's 30-90 g) that
  decays over the run, larger with heavier loads and none without a load. The thread's own mass and the pulley's
  inertia are left out.
* ``relay_coil_decoy`` -- a decoy, no effect on the motor: logged ``relay_coil_temp_C`` per sample, a thermistor on
  the coil of the relay that swaps the drive's CH1 and CH2 for backward runs (glued there after a relay burned out).
  The DAQ program energises the relay for each backward run and releases it at the run's end; the coil's
  temperature follows its dissipation first order on the session clock, ``d theta/dt = (Theta on - theta) / tau``
  (``on`` 1 during a backward run, else 0; ``Theta`` drawn in 25-40 K, the coil's rise when held on; ``tau`` in
  15-30 s), ``25 degC + theta``, 0.05 K of noise and 0.01 K resolution. It follows the session clock, and the
  direction and the time in a run through a rise of 0.15-1.1 K within each backward run (longer for slower runs);
  the relay's contacts are closed either way, so it acts on nothing: it must
  not be traced.

Pass rule (fixed before any loop ran; the eighth, ninth and tenth audits'): a kind passes when a regressor of
``WANT`` is among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse
before and after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean
SEED``). The decoy passes when ``relay_coil_temp_C`` is nowhere in ``traced_all`` and ``a <= 1.02 b``. ``WANT``: the
torque column for the clamp; for the film, a regressor of the runs before (its name holds ``_lag``, ``prev`` or
``last``: the previous run's condition, a low-pass of the runs before); for the thread, a regressor of the time in
the run or of the motion's start or acceleration (its name holds ``time_in_run``, ``onset``, ``start``, ``accel``
or ``inertia``; a position is not accepted: the ringing runs in time, the distance from the start end is only its
proxy).

Usage: python bench/blind_effects_eleventh.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run nrmse before
and after, channels considered, CPU of the close loop by ``time.process_time``), plus ``traced_all`` (every traced
regressor) and ``want`` (the regressors accepted as the effect's).
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)
import blind_effects_fifth as b5  # noqa: E402

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.physics.slider import G_M_S2  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("clamp_torque_damping", "film_carryover", "elastic_load_line", "relay_coil_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"clamp_torque_damping": "clamp_torque_cNm", "film_carryover": None, "elastic_load_line": None,
           "relay_coil_decoy": "relay_coil_temp_C"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"clamp_torque_damping": ("clamp_torque_cNm",),
        "film_carryover": ("_lag", "prev", "last"),
        "elastic_load_line": ("time_in_run", "onset", "start", "accel", "inertia"),
        "relay_coil_decoy": ()}
TORQUE_REF_CNM = 30.0       # the clamping torque at which the motor's own zeta_l holds
FILM_V_REF_M_S = 0.2        # the speed whose film the motor's own mu_p meets (and the warm-up pass's)
SUB_STEPS = 10              # the thread's sub-steps per co-simulation step


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 131, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "clamp_torque_damping":
        return {"s": float(rng.uniform(0.25, 0.35)), "tau0_cNm": float(rng.uniform(8.0, 14.0)),
                "torque_cNm": rng.uniform(20.0, 70.0, n_runs)}
    if kind == "film_carryover":
        return {"B": float(rng.uniform(0.15, 0.25))}
    if kind == "elastic_load_line":
        return {"k_N_per_m": float(rng.uniform(200.0, 500.0)), "eta": float(rng.uniform(0.04, 0.10))}
    if kind == "relay_coil_decoy":
        return {"Theta_K": float(rng.uniform(25.0, 40.0)), "tau_s": float(rng.uniform(15.0, 30.0))}
    return {}


def clamp_zeta(zeta_l: float, torque_cNm, s: float, tau0_cNm: float):
    """L1's damping ratio at the clamping torque ``torque_cNm``: ``zeta_l (1 - s + s exp(-(tau - 30) / tau0))``."""
    return zeta_l * (1.0 - s + s * np.exp(-(np.asarray(torque_cNm, float) - TORQUE_REF_CNM) / tau0_cNm))


def film_factor(v_prev_m_s: float, B: float) -> float:
    """The slip friction's factor on the film the previous pass at ``v_prev_m_s`` [m/s] left:
    ``1 - B ((v_prev / 0.2 m/s)^(2/3) - 1)``."""
    return 1.0 - B * ((abs(float(v_prev_m_s)) / FILM_V_REF_M_S) ** (2.0 / 3.0) - 1.0)


def thread_law(L: float, s0: float, k: float, eta: float):
    """The load input [kg] of a weight ``L`` hung on an elastic thread, as a law of ``(t, s, v)``: ``sign(L) T / g``
    with ``T`` the thread's tension (see the module's docstring); the weight's motion is integrated over each
    co-simulation step in :data:`SUB_STEPS` sub-steps, the slider's travel ``q`` interpolated linearly; ``s0`` is
    the run's start position."""
    m, sgn = abs(L), (1.0 if L > 0 else -1.0)
    c = eta * k / math.sqrt(k / m)
    st = {"t": 0.0, "q": 0.0, "z": 0.0, "zd": 0.0, "T": m * G_M_S2}

    def law(t, s, v):
        if t <= st["t"]:
            return sgn * st["T"] / G_M_S2
        q1, qd = -sgn * (s - s0), -sgn * v          # travel toward the pulley (positive load: toward -position)
        n, dt = SUB_STEPS, (t - st["t"]) / SUB_STEPS
        q, z, zd, T = st["q"], st["z"], st["zd"], st["T"]
        for i in range(n):
            qi = q + (q1 - q) * (i + 1) / n
            T = max(0.0, m * G_M_S2 + k * (z - qi) + c * (zd - qd))
            zd += (G_M_S2 - T / m) * dt
            z += zd * dt
        st.update(t=t, q=q1, z=z, zd=zd, T=T)
        return sgn * T / G_M_S2
    return law


def relay_theta(t_rel, theta0: float, on: bool, Theta: float, tau: float):
    """The coil's rise [K] at the times ``t_rel`` [s] after a segment's start from ``theta0``: toward ``Theta``
    when ``on``, toward 0 otherwise (first order, ``tau``)."""
    target = Theta if on else 0.0
    return target + (theta0 - target) * np.exp(-np.asarray(t_rel, float) / tau)


def run_traverse(kind, mp, nominal, plan, V, L, d, p):
    """``(record, motor)`` of one run of ``kind`` (the thread's load law for the elastic line)."""
    if kind == "elastic_load_line" and L != 0:
        if mp.slider.pulley_mu != 0:
            raise ValueError("elastic_load_line moves the load's inertia into the thread: it needs pulley_mu = 0")
        mp = mp.replace(slider__load_inertia=0.0)
        s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
        law = thread_law(L, s0, p["k_N_per_m"], p["eta"])
        r, _ = b5.traverse(mp, nominal, plan, V, L, d, None, law)
        return r, mp
    return be.traverse(mp, nominal, plan, V, L, d), mp


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next = [], [], 0.0
    v_prev, theta, t_end_prev = FILM_V_REF_M_S, 0.0, 0.0
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        if kind == "clamp_torque_damping":
            mp = mp.replace(stator__zeta_l=float(clamp_zeta(mp.stator.zeta_l, p["torque_cNm"][k], p["s"],
                                                            p["tau0_cNm"])))
        elif kind == "film_carryover":
            mp = mp.replace(interface__mu_p=mp.interface.mu_p * film_factor(v_prev, p["B"]))
        r, mp = run_traverse(kind, mp, nominal, plan, V, L, d, p)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 132, k]).standard_normal(len(t))
        if kind == "clamp_torque_damping":
            extra["clamp_torque_cNm"] = np.round(p["torque_cNm"][k] + 0.2 * noise, 1)
        elif kind == "relay_coil_decoy":
            theta = float(relay_theta(t_next - t_end_prev, theta, False, p["Theta_K"], p["tau_s"]))  # the pause
            th = relay_theta(t, theta, d < 0, p["Theta_K"], p["tau_s"])
            extra["relay_coil_temp_C"] = np.round(25.0 + th + 0.05 * noise, 2)
            theta = float(relay_theta(float(r["time"][-1]), theta, d < 0, p["Theta_K"], p["tau_s"]))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, **extra)
        frames.append(out)
        dur = float(r["time"][-1])
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "zeta_l": mp.stator.zeta_l, "v_prev_m_s": v_prev, "duration_s": dur})
        v_prev = abs(float(r["Slider.s"][-1] - r["Slider.s"][0])) / dur if dur > 0 else FILM_V_REF_M_S
        t_end_prev = t_next + dur
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.want_fields(CHANNEL, WANT))


if __name__ == "__main__":
    main()
