#!/usr/bin/env python
"""A sixth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the loop
and no kind of the five earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py``, ``bench/blind_effects_fourth.py``, ``bench/blind_effects_fifth.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``velocity_clip`` -- a data-quality effect of the recorded speed itself. The speed column comes from a velocity
  decoder whose analogue output is read by an ADC of +-10 V; the operator chose a scale factor that puts the
  rails at +-v_rail (drawn in 0.19-0.22 m/s, a decoder range picked below the fastest runs' speed), so the
  recorded speed is ``clip(v + noise, -v_rail, v_rail)``: the fastest runs read flat at the rail (the position,
  from the encoder, is not clipped).
* ``velocity_clip_noisy`` -- the same decoder and the same draws (its rail, the plan's speed noise), but the
  decoder's analogue output saturates first (at +-v_rail, its +-5 V output stage) and the noise and the ADC's
  quantisation come after it: an ADC of +-10 V and 12 bits reads ``q round((clip(v, -v_rail, v_rail) + noise) /
  q)`` with ``q = 4 v_rail / 4096`` (never at its own full scale), so the fastest runs' samples scatter around
  the rail by the noise instead of repeating one value.
* ``holder_damping_nan`` -- logged auxiliary ``holder_temp_C`` per sample, with gaps written as NaN. The stator
  sits in a polymer holder that takes part of each mode's strain energy; the polymer's loss factor rises with its
  temperature near its glass transition (a polyurethane holder with its transition at room temperature), so
  both modes' damping ratios scale as ``zeta (1 + beta (T - 25 degC))`` (beta drawn in 0.06-0.08 /K). The
  holder's temperature differs from run to run (the enclosure's air cycles; drawn uniform in 20-32 degC per run)
  and is logged by a thermocouple (0.05 K noise, 0.01 K resolution) whose amplifier flags an open circuit now and
  then: in a run, with probability 0.3, a burst of 5-40 samples is written as NaN (an empty cell in the CSV).
* ``heatsink_decoy`` -- a decoy, no effect on the motor: logged ``amp_heatsink_C`` per sample, the drive
  amplifier's heat-sink temperature. The amplifier's output is regulated, so its temperature does not reach the
  motor; it heats during each run toward ``25 + 12 (V0 / 324 V)^2`` degC and cools in the pauses toward 27 degC
  (idle dissipation), first order with tau drawn in 3-6 s, so it follows the plan's voltage, the session clock and
  (within a run) the stroke. 0.05 K noise, 0.01 K resolution. It must not be traced.
* ``piezo_deaging`` -- no channel; a memory of the previous runs' drive. A hard PZT driven at high ac field
  de-ages: the field unpins domain walls that the internal bias field held, which raises the piezoelectric
  coefficient, and it re-ages when the field is off. The de-aged share ``h`` is an exponential average over the
  previous runs of their ``(V0 / 324 V)^2``, ``h_(k+1) = r h_k + (1 - r) (V0_k / 324 V)^2``, ``h_0 = 0`` (an aged
  part at the session's start; r drawn in 0.6-0.85 per run), and both modes' force factors are
  ``A (1 + delta h_k)`` (delta drawn in 0.10-0.16). Run k's motor depends on the runs before it, not on its own
  setting.

Usage: python bench/blind_effects_sixth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
clean). Prints one JSON line as ``bench/blind_effects.py`` does (traced first two, added, TEST free-run nrmse before
and after, channels considered, CPU of the close loop by ``time.process_time``), plus ``traced_all`` (every traced
regressor).
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402  (adds fmu_src to the path)

from l1b2.data import measurements as dataio  # noqa: E402
from l1b2.rig.experiment import scattered_motor  # noqa: E402

KINDS = ("velocity_clip", "holder_damping_nan", "heatsink_decoy", "piezo_deaging", "velocity_clip_noisy")
#: the channel each kind acts through (the decoy's: the column that must NOT be traced)
CHANNEL = {"velocity_clip": "speed", "velocity_clip_noisy": "speed", "holder_damping_nan": "holder_temp_C", "heatsink_decoy": "amp_heatsink_C",
           "piezo_deaging": "time or a lag of voltage"}
V_REF_V = 324.0
T_REF_C = 25.0


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    kind = {"velocity_clip_noisy": "velocity_clip"}.get(kind, kind)     # the same decoder, the same draws
    rng = np.random.default_rng([seed, 91, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "velocity_clip":
        return {"v_rail_m_s": float(rng.uniform(0.19, 0.22))}
    if kind == "holder_damping_nan":
        return {"beta_per_K": float(rng.uniform(0.06, 0.08)), "T_C": rng.uniform(20.0, 32.0, n_runs),
                "gap": rng.uniform(0.0, 1.0, n_runs) < 0.3, "gap_len": rng.integers(5, 41, n_runs),
                "gap_at": rng.uniform(0.0, 1.0, n_runs)}
    if kind == "heatsink_decoy":
        return {"tau_s": float(rng.uniform(3.0, 6.0))}
    if kind == "piezo_deaging":
        return {"r": float(rng.uniform(0.6, 0.85)), "delta": float(rng.uniform(0.10, 0.16))}
    return {}


def clip_speed(v_m_s, v_rail_m_s: float):
    """The speed [m/s] an ADC reads from a decoder whose rails sit at +-``v_rail_m_s``."""
    return np.clip(np.asarray(v_m_s, float), -v_rail_m_s, v_rail_m_s)


#: the noisy rail's ADC: +-10 V, 12 bits, the decoder's rails at +-5 V (so the quantum is 4 v_rail / 4096)
ADC_SPAN_PER_RAIL, ADC_CODES = 4.0, 4096


def quantise_speed(v_m_s, v_rail_m_s: float):
    """The speed [m/s] that the noisy rail's ADC writes: its nearest code (quantum ``4 v_rail / 4096``)."""
    q = ADC_SPAN_PER_RAIL * v_rail_m_s / ADC_CODES
    return q * np.round(np.asarray(v_m_s, float) / q)


def holder_damping(zeta, T_C, beta_per_K: float):
    """A mode's damping ratio with its holder at ``T_C`` [degC]: ``zeta (1 + beta (T - 25 degC))``."""
    return np.asarray(zeta, float) * (1.0 + beta_per_K * (np.asarray(T_C, float) - T_REF_C))


def with_gap(values, gap: bool, length: int, at: float):
    """``values`` with a burst of ``length`` samples set to NaN starting at the fraction ``at`` of the run (none
    unless ``gap``)."""
    out = np.array(values, float)
    if gap and out.size:
        i0 = min(int(at * out.size), max(out.size - length, 0))
        out[i0:i0 + length] = np.nan
    return out


def heatsink_path(t_run_s, V0_V: float, T_start_C: float, tau_s: float):
    """The heat sink's temperature [degC] at the run's times ``t_run_s`` (from the run's start), heating first order
    toward ``25 + 12 (V0 / 324 V)^2`` degC from ``T_start_C``."""
    T_inf = T_REF_C + 12.0 * (V0_V / V_REF_V) ** 2
    return T_inf + (T_start_C - T_inf) * np.exp(-np.asarray(t_run_s, float) / tau_s)


def heatsink_pause(T_end_C: float, pause_s: float, tau_s: float, T_idle_C: float = 27.0) -> float:
    """The heat sink's temperature [degC] after a pause of ``pause_s``, cooling toward ``T_idle_C``."""
    return T_idle_C + (T_end_C - T_idle_C) * float(np.exp(-pause_s / tau_s))


def deaging_share(V0_V, r: float):
    """The de-aged share ``h_k`` before each run k: ``h_0 = 0``, ``h_(k+1) = r h_k + (1 - r) (V0_k / 324 V)^2``."""
    out, h = np.empty(len(V0_V)), 0.0
    for k, V in enumerate(V0_V):
        out[k] = h
        h = r * h + (1.0 - r) * (float(V) / V_REF_V) ** 2
    return out


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    h = deaging_share([c[0] for c in conds], p["r"]) if kind == "piezo_deaging" else None
    frames, per_run, t_next, T_hs = [], [], 0.0, 27.0
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        st = mp.stator
        if kind == "holder_damping_nan":
            T = p["T_C"][k]
            mp = mp.replace(stator__zeta_l=float(holder_damping(st.zeta_l, T, p["beta_per_K"])),
                            stator__zeta_b=float(holder_damping(st.zeta_b, T, p["beta_per_K"])))
        elif kind == "piezo_deaging":
            g = 1.0 + p["delta"] * h[k]
            mp = mp.replace(stator__A_l_N_per_V=st.A_l_N_per_V * g, stator__A_b_N_per_V=st.A_b_N_per_V * g)
        r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t = r["time"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 92, k]).standard_normal(len(t))
        if kind == "holder_damping_nan":
            logged = np.round(p["T_C"][k] + 0.05 * noise, 2)
            extra["holder_temp_C"] = with_gap(logged, bool(p["gap"][k]), int(p["gap_len"][k]), p["gap_at"][k])
        elif kind == "heatsink_decoy":
            path = heatsink_path(t - t[0], V, T_hs, p["tau_s"])
            extra["amp_heatsink_C"] = np.round(path + 0.05 * noise, 2)
        out = be.daq_frame(plan, t_next, k, t, r["Slider.s"][idx], V, L, d, **extra)
        if kind == "velocity_clip_noisy":       # the analogue stage saturates before the noise is added
            out[dataio.SPEED] = clip_speed(out[dataio.SPEED].to_numpy(float), p["v_rail_m_s"])
        frames.append(out)
        per_run.append({"run": k + 1, "zeta_l": mp.stator.zeta_l, "zeta_b": mp.stator.zeta_b,
                        "A_l_N_per_V": mp.stator.A_l_N_per_V, "heatsink_start_C": T_hs,
                        "deaged_share": None if h is None else float(h[k])})
        t_end = float(out[dataio.TIME].iloc[-1])
        if kind == "heatsink_decoy":
            T_run_end = float(heatsink_path(t[-1] - t[0], V, T_hs, p["tau_s"]))
            T_hs = heatsink_pause(T_run_end, plan.pause_s, p["tau_s"])
        t_next = t_end + plan.pause_s
    df, truth, nominal, plan = be.finish(kind, frames, per_run, p, nominal, plan)
    if kind == "velocity_clip":
        df[dataio.SPEED] = clip_speed(df[dataio.SPEED].to_numpy(float), p["v_rail_m_s"])
    elif kind == "velocity_clip_noisy":
        df[dataio.SPEED] = quantise_speed(df[dataio.SPEED].to_numpy(float), p["v_rail_m_s"])
    return df, truth, nominal, plan


def row_extra(kind: str) -> dict:
    """The printed row's extra fields: the kind's channel, every traced regressor, the auxiliary columns with NaN."""
    return {"channel": lambda names, diag: CHANNEL.get(kind),
            "traced_all": lambda names, diag: list(diag["traced_to"])}


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, row_extra)

if __name__ == "__main__":
    main()
