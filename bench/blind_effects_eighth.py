#!/usr/bin/env python
"""An eighth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the seven earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py``, ``bench/blind_effects_fourth.py``, ``bench/blind_effects_fifth.py``,
``bench/blind_effects_sixth.py``, ``bench/blind_effects_seventh.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``vacuum_squeeze_film`` -- logged ``chamber_pressure_hPa`` per sample, a Pirani gauge (1 % noise, 0.01 hPa
  resolution): the rig sits in a vacuum chamber (a space-qualification campaign) whose leak-valve controller sets a
  new pressure for each run, log-uniform over 1-1000 hPa (a design factor). B2 bends in the plate's plane, so the
  plate's narrow 30 x 3 mm edge faces move normal to themselves against the holder's side walls across an air gap
  ``h`` (drawn in 8-15 um); the air squeezed in that gap is a share ``s`` (drawn in 0.30-0.45) of B2's damping at
  the lab's 1013.25 hPa. The film's effective viscosity falls as the gas rarefies, with the Knudsen number ``Kn =
  lambda_0 (1013.25 hPa / p) / h`` (``lambda_0`` = 68 nm, air's mean free path at 1013.25 hPa) by Veijola's fit
  ``1 / (1 + 9.638 Kn^1.159)``, so ``zeta_b(p) = zeta_b (1 - s + s g(p) / g(1013.25 hPa))`` with ``g`` that fit:
  flat near the lab's pressure, falling over 100-10 hPa, flat again below (a saturating law of the pressure's
  logarithm). L1's motion is normal to the plate's 7.5 x 3 mm end faces, far from any wall: left as it is.
* ``file_write_latency`` -- no column; a recording-protocol state carried over from the previous run. The DAQ
  program starts each run's acquisition on the operator's trigger, then writes the previous run's samples to its
  file (text, ``w`` per sample, drawn in 0.04-0.08 ms), and only then closes the drive's relay (operate time drawn
  in 6-12 ms, plus a jitter uniform in 0-4 ms per run). So each run's record begins with ``d_k = relay + w N_(k-1)
  + jitter`` of the slider at rest at its start end, with the drive logged at its V0 (``N_(k-1)``: the previous
  run's number of samples, 0 before the first run): 8-70 ms, longer after a slow run. The motion itself is
  unchanged.
* ``encoder_cyclic_error`` -- a measurement-chain effect on the position column (the logged position is not the
  slider's). The encoder is a magnetic scale of pole pitch ``P`` (drawn in 1-2 mm) whose read head interpolates
  its sine and cosine; their offsets and amplitude mismatch (the head mounted at the limit of its ride height)
  give the classic sub-divisional error, ``e(s) = A1 sin(2 pi s / P + phi1) + A2 sin(4 pi s / P + phi2)`` (A1
  drawn in 6-10 um, A2 in 2-4 um, phases uniform), so the logged position is ``s + e(s)`` and the speed the DAQ
  derives from it ripples at v/P and 2 v/P (25-460 Hz over the plan's speeds). The motion is unchanged.
* ``strain_gauge_decoy`` -- a decoy, no effect on the motor: logged ``pulley_strain_ue`` per sample, a foil strain
  gauge on the bracket of the pulley that carries the positive loads (the negative loads hang over the other end's
  pulley, whose bracket has no gauge). It reads the cable's pull, ``k g max(m, 0)`` (k drawn in 20-30 ue/N), plus
  its apparent strain with the lab's air, ``alpha dT(t)`` (alpha drawn in 5-10 ue/K; the air-conditioning's cycle
  ``dT = A_T sin(2 pi t / Pi + phi)`` on the session clock, A_T drawn in 0.5-1.0 K, Pi in 150-250 s), 0.5 ue of noise
  and 0.1 ue resolution. It follows a factor of the plan (the load, one-sided) and the clock, not the speed, and acts
  on nothing: it must not be traced.

Pass rule (fixed before any loop ran; 0053's, 0089's and 0101's): a kind passes when a regressor of ``WANT`` is
among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before and
after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``). The decoy
passes when ``pulley_strain_ue`` is nowhere in ``traced_all`` and ``a <= 1.02 b``. ``WANT``: the pressure column
for the vacuum; a regressor of the run's start (its name holds ``delay``, ``dead``, ``start``, ``onset`` or
``latency``) for the write latency; ``position`` or ``speed`` (a position-periodic term, or the loop's
measurement chain) for the encoder.

Usage: python bench/blind_effects_eighth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
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

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("vacuum_squeeze_film", "file_write_latency", "encoder_cyclic_error", "strain_gauge_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"vacuum_squeeze_film": "chamber_pressure_hPa", "file_write_latency": None,
           "encoder_cyclic_error": "position_m", "strain_gauge_decoy": "pulley_strain_ue"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran)
WANT = {"vacuum_squeeze_film": ("chamber_pressure_hPa",),
        "file_write_latency": ("delay", "dead", "start", "onset", "latency"),
        "encoder_cyclic_error": ("position", "speed"), "strain_gauge_decoy": ()}
P_REF_HPA = 1013.25
MFP_REF_M = 68e-9
SAMPLE_S = 1e-3
G_M_S2 = 9.81


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 108, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "vacuum_squeeze_film":
        return {"share": float(rng.uniform(0.30, 0.45)), "gap_m": float(rng.uniform(8e-6, 15e-6)),
                "p_hPa": np.exp(rng.uniform(math.log(1.0), math.log(1000.0), n_runs))}
    if kind == "file_write_latency":
        return {"relay_s": float(rng.uniform(6e-3, 12e-3)), "w_s": float(rng.uniform(0.04e-3, 0.08e-3)),
                "jitter_s": rng.uniform(0.0, 4e-3, n_runs)}
    if kind == "encoder_cyclic_error":
        return {"P_m": float(rng.uniform(1e-3, 2e-3)), "A1_m": float(rng.uniform(6e-6, 10e-6)),
                "A2_m": float(rng.uniform(2e-6, 4e-6)), "phi1": float(rng.uniform(0, 2 * math.pi)),
                "phi2": float(rng.uniform(0, 2 * math.pi))}
    if kind == "strain_gauge_decoy":
        return {"k_ue_N": float(rng.uniform(20.0, 30.0)), "alpha_ue_K": float(rng.uniform(5.0, 10.0)),
                "A_T_K": float(rng.uniform(0.5, 1.0)), "Pi_s": float(rng.uniform(150.0, 250.0)),
                "phi": float(rng.uniform(0, 2 * math.pi))}
    return {}


def film_factor(p_hPa, gap_m: float):
    """Veijola's rarefied-gas factor of a squeeze film's viscosity, ``1 / (1 + 9.638 Kn^1.159)``, at the pressure
    ``p_hPa`` [hPa] across the gap ``gap_m`` [m] (``Kn = 68 nm (1013.25 hPa / p) / gap``)."""
    kn = MFP_REF_M * (P_REF_HPA / np.asarray(p_hPa, float)) / gap_m
    return 1.0 / (1.0 + 9.638 * kn ** 1.159)


def b2_damping(zeta_b: float, p_hPa, share: float, gap_m: float):
    """B2's damping ratio at the pressure ``p_hPa`` [hPa]: ``zeta_b (1 - s + s g(p) / g(1013.25 hPa))``."""
    return zeta_b * (1.0 - share + share * film_factor(p_hPa, gap_m) / film_factor(P_REF_HPA, gap_m))


def start_latency_s(n_prev, relay_s: float, w_s: float, jitter_s):
    """The delay [s] from the trigger to the drive's start: ``relay + w N_(k-1) + jitter``."""
    return relay_s + w_s * np.asarray(n_prev, float) + np.asarray(jitter_s, float)


def delayed_samples(t_sim_s, s_sim_m, delay_s: float, step_s: float = SAMPLE_S):
    """``(t, s)``: the DAQ's samples every ``step_s`` [s] from the trigger of a motion ``s_sim_m(t_sim_s)`` [m]
    (``t_sim_s`` from 0) that starts ``delay_s`` [s] after it; the slider rests at ``s_sim_m[0]`` before, and the
    record ends with the motion's last time."""
    t_sim = np.asarray(t_sim_s, float)
    n = int(math.floor((t_sim[-1] + delay_s) / step_s + 1e-9)) + 1
    t = np.arange(n) * step_s
    return t, np.interp(t - delay_s, t_sim, np.asarray(s_sim_m, float))


def cyclic_error_m(s_m, P_m: float, A1_m: float, A2_m: float, phi1: float, phi2: float):
    """The encoder's sub-divisional error [m] at the position ``s_m`` [m]: ``A1 sin(2 pi s / P + phi1) + A2 sin(4 pi
    s / P + phi2)``."""
    x = 2.0 * math.pi * np.asarray(s_m, float) / P_m
    return A1_m * np.sin(x + phi1) + A2_m * np.sin(2.0 * x + phi2)


def gauge_strain_ue(load_kg, t_s, k_ue_N: float, alpha_ue_K: float, A_T_K: float, Pi_s: float, phi: float):
    """The pulley bracket's gauge [ue] without noise: ``k g max(m, 0) + alpha A_T sin(2 pi t / Pi + phi)``."""
    t = np.asarray(t_s, float)
    return k_ue_N * G_M_S2 * np.maximum(np.asarray(load_kg, float), 0.0) \
        + alpha_ue_K * A_T_K * np.sin(2.0 * math.pi * t / Pi_s + phi)


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next, n_prev = [], [], 0.0, 0
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        if kind == "vacuum_squeeze_film":
            mp = mp.replace(stator__zeta_b=float(b2_damping(mp.stator.zeta_b, p["p_hPa"][k], p["share"],
                                                               p["gap_m"])))
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra, s_log, delay = {}, s, 0.0
        if kind == "file_write_latency":
            delay = float(start_latency_s(n_prev, p["relay_s"], p["w_s"], p["jitter_s"][k]))
            t, s = delayed_samples(r["time"], r["Slider.s"], delay)
            s_log = s
        noise = np.random.default_rng([seed, 109, k]).standard_normal(len(t))
        if kind == "vacuum_squeeze_film":
            extra["chamber_pressure_hPa"] = np.round(p["p_hPa"][k] * (1.0 + 0.01 * noise), 2)
        elif kind == "encoder_cyclic_error":
            s_log = s + cyclic_error_m(s, p["P_m"], p["A1_m"], p["A2_m"], p["phi1"], p["phi2"])
        elif kind == "strain_gauge_decoy":
            eps = gauge_strain_ue(L, t_next + t, p["k_ue_N"], p["alpha_ue_K"], p["A_T_K"], p["Pi_s"], p["phi"])
            extra["pulley_strain_ue"] = np.round(eps + 0.5 * noise, 1)
        out = be.daq_frame(plan, t_next, k, t, s_log, V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "zeta_b": mp.stator.zeta_b, "delay_s": delay, "n_samples": len(t)})
        n_prev = len(t)
        t_next = float(out[dataio.TIME].iloc[-1]) + plan.pause_s
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.want_fields(CHANNEL, WANT))


if __name__ == "__main__":
    main()
