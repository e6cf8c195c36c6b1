#!/usr/bin/env python
"""A seventh blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the six earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py``, ``bench/blind_effects_fourth.py``, ``bench/blind_effects_fifth.py``,
``bench/blind_effects_sixth.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``holder_clamp_force`` -- logged ``holder_force_N`` per sample, a force sensor (a piezoelectric load washer under
  the stator holder's clamping screw), not a temperature; it acts on the L1 resonance, which no earlier kind moved.
  The holding force is a factor of the design, randomised per run (uniform 15-90 N). The holder's pads grip the
  plate at its centre, where the L1 mode's axial strain (a node of its displacement) is largest; their Hertzian
  contact stiffness grows as ``F^(1/3)`` and constrains the plate there, so L1's free frequency rises with the
  force, ``f_l0 + K ((F / 50 N)^(1/3) - 1)`` (K drawn in 1400-1800 Hz: -0.9..+0.8 % of L1 over the range). B2 bends
  in the plate's plane, which the pads on its thickness faces barely hold: it is left as it is. The washer reads
  the force with 0.2 N of noise per sample (0.01 N resolution).
* ``guide_rest_idle`` -- a control of ``guide_rest_aging``: its seed's pauses (the same draw), a guide that does not
  age (``B = 0``). Nothing is injected, so nothing may be traced to the rests (``WANT`` empty).
* ``guide_rest_aging`` -- no channel; a state that changes between runs only. The operator's pauses between runs
  are not the plan's 1 s but spread log-uniformly over 0.5-30 s (saving files, a look at the scope); the session
  starts after 60 s at rest. At rest, the crossed-roller guide's rollers squeeze the grease film out of their line
  contacts, and the film rebuilds only once they roll: the guide's friction after a rest ``t_r`` follows a
  logarithmic ageing law (as contact ageing in rate-and-state friction), ``mu (1 + B ln(1 + t_r / theta)) / (1 + B
  ln(1 + 1 s / theta))`` for both the guide's dynamic and static coefficients (B drawn in 0.05-0.08, theta in
  0.1-0.3 s; normalised so that the plan's 1 s pause gives the motor's own guide). Only the clock's gaps carry the
  rest times.
* ``usb_timestamps`` -- a measurement-chain effect on the time column. The DAQ samples the encoder on its own
  1 kHz clock and sends packets of N samples (N drawn in 10-25 per session) over USB; the host stamps each packet on
  arrival, after a latency uniform in 0-L_max (L_max drawn in 0.3-0.6 ms, under a full-speed frame), and back-dates
  the packet's samples at the nominal 1 ms. So the logged ``time_s`` of a sample is its true time plus its packet's
  latency: steps of 1 ms within a packet and of ``1 ms + L_(p+1) - L_p`` across packet boundaries (always
  positive: the clock stays strictly increasing). The host computes the speed column from the position over the
  stamps it logs (the DAQ frame's derivative), so the speed steps at each packet boundary. The motion is not
  changed.
* ``acoustic_echo_decoy`` -- a decoy, no effect on the motor: logged ``mic_level_dB`` per sample, a sound level
  meter (fast time weighting, 125 ms) beside the guide. The guide's rolling noise has a sound power proportional to
  the square of the slider's speed, ``L = 10 log10(10^(L_bg/10) + 10^(L_1/10) <(v / 0.2 m/s)^2>)`` (L_1 drawn in
  55-62 dB, background L_bg in 38-42 dB; ``<.>`` the meter's first-order average, from the background at each run's
  start: the pause is 8 time constants), 0.1 dB of noise and resolution. The column is a consequence of the speed
  (it echoes the run-to-run scatter and every effect on the speed), not a cause: it must not be traced.

Usage: python bench/blind_effects_seventh.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
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

KINDS = ("holder_clamp_force", "guide_rest_aging", "usb_timestamps", "acoustic_echo_decoy", "guide_rest_idle")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"holder_clamp_force": "holder_force_N", "guide_rest_aging": None, "usb_timestamps": "time_s",
           "acoustic_echo_decoy": "mic_level_dB", "guide_rest_idle": None}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran): the
#: channel's own name, a regressor of the session clock for the rests, the time or speed chain for the stamps;
#: the decoy has none (its column must not be traced at all)
WANT = {"holder_clamp_force": ("holder_force_N",), "guide_rest_aging": ("time", "pause"),
        "usb_timestamps": ("time", "speed"), "acoustic_echo_decoy": (), "guide_rest_idle": ()}
#: the kinds whose operator pauses irregularly between runs
RESTS = ("guide_rest_aging", "guide_rest_idle")
F_REF_N = 50.0
REST_REF_S = 1.0
FIRST_REST_S = 60.0
SAMPLE_S = 1e-3
V_NOISE_REF_M_S = 0.2
METER_TAU_S = 0.125


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    if kind == "guide_rest_idle":   # the rests' own pauses, a guide that does not age
        return {**draw("guide_rest_aging", seed, n_runs), "B": 0.0}
    rng = np.random.default_rng([seed, 101, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "holder_clamp_force":
        return {"K_Hz": float(rng.uniform(1400.0, 1800.0)), "F_N": rng.uniform(15.0, 90.0, n_runs)}
    if kind == "guide_rest_aging":
        return {"B": float(rng.uniform(0.05, 0.08)), "theta_s": float(rng.uniform(0.1, 0.3)),
                "pause_s": np.exp(rng.uniform(math.log(0.5), math.log(30.0), n_runs))}
    if kind == "usb_timestamps":
        return {"N": int(rng.integers(10, 26)), "L_max_s": float(rng.uniform(0.3e-3, 0.6e-3)),
                "u": rng.uniform(0.0, 1.0, 4000 * n_runs)}
    if kind == "acoustic_echo_decoy":
        return {"L1_dB": float(rng.uniform(55.0, 62.0)), "Lbg_dB": float(rng.uniform(38.0, 42.0))}
    return {}


def l1_frequency_Hz(f_l0_Hz, F_N, K_Hz: float):
    """L1's free frequency [Hz] with the holder clamped at ``F_N`` [N]: ``f_l0 + K ((F / 50 N)^(1/3) - 1)``."""
    return np.asarray(f_l0_Hz, float) + K_Hz * (np.cbrt(np.asarray(F_N, float) / F_REF_N) - 1.0)


def rest_factor(rest_s, B: float, theta_s: float):
    """The guide's friction after a rest of ``rest_s`` [s] over its friction after the plan's 1 s rest."""
    return (1.0 + B * np.log1p(np.asarray(rest_s, float) / theta_s)) / (1.0 + B * math.log1p(REST_REF_S / theta_s))


def packet_stamps(t_s, N: int, latency_s):
    """The host's stamps [s] of samples taken at ``t_s`` (the DAQ's clock, from 0 at the run's start) sent in packets
    of ``N``: each sample's true time plus its packet's latency (``latency_s[p]`` for the p-th packet)."""
    t = np.asarray(t_s, float)
    return t + np.asarray(latency_s, float)[np.arange(t.size) // N]


def meter_level_dB(t_s, v_m_s, L1_dB: float, Lbg_dB: float, tau_s: float = METER_TAU_S):
    """A sound level meter's reading [dB] of a guide whose noise power is ``10^(L1/10) (v / 0.2 m/s)^2`` over the
    background ``10^(Lbg/10)``: the power through the meter's first-order average (exact for a power held over each
    step), starting from the background."""
    t = np.asarray(t_s, float)
    src = 10.0 ** (L1_dB / 10.0) * (np.asarray(v_m_s, float) / V_NOISE_REF_M_S) ** 2
    avg = np.empty_like(src)
    a = 0.0
    for k in range(t.size):
        if k:
            w = math.exp(-(t[k] - t[k - 1]) / tau_s)
            a = w * a + (1.0 - w) * src[k - 1]
        avg[k] = a
    return 10.0 * np.log10(10.0 ** (Lbg_dB / 10.0) + avg)


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next, u_at = [], [], FIRST_REST_S if kind in RESTS else 0.0, 0
    rest = FIRST_REST_S
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        if kind == "holder_clamp_force":
            mp = mp.replace(stator__f_l0_Hz=float(l1_frequency_Hz(mp.stator.f_l0_Hz, p["F_N"][k], p["K_Hz"])))
        elif kind in RESTS:
            g = float(rest_factor(rest, p["B"], p["theta_s"]))
            mp = mp.replace(slider__mu_sd=mp.slider.mu_sd * g, slider__mu_ss=mp.slider.mu_ss * g)
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra, t_log = {}, t
        noise = np.random.default_rng([seed, 102, k]).standard_normal(len(t))
        if kind == "holder_clamp_force":
            extra["holder_force_N"] = np.round(p["F_N"][k] + 0.2 * noise, 2)
        elif kind == "usb_timestamps":
            n_packets = -(-len(t) // p["N"])
            lat = p["u"][u_at:u_at + n_packets] * p["L_max_s"]
            u_at += n_packets
            t_log = packet_stamps(t, p["N"], lat)
        elif kind == "acoustic_echo_decoy":
            level = meter_level_dB(t, np.gradient(s, t), p["L1_dB"], p["Lbg_dB"])
            extra["mic_level_dB"] = np.round(level + 0.1 * noise, 1)
        out = be.daq_frame(plan, t_next, k, t_log, s, V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "f_l0_Hz": mp.stator.f_l0_Hz, "mu_sd": mp.slider.mu_sd, "rest_s": rest})
        rest = float(p["pause_s"][k]) if kind in RESTS else plan.pause_s
        t_next = float(out[dataio.TIME].iloc[-1]) + rest
    if kind == "usb_timestamps":
        p = {k: v for k, v in p.items() if k != "u"}
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.want_fields(CHANNEL, WANT))


if __name__ == "__main__":
    main()
