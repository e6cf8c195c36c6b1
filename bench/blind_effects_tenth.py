#!/usr/bin/env python
"""A tenth blind audit of the close loop: four more kinds that no injection of the rig, no candidate form of the
loop and no kind of the nine earlier audits (``bench/blind_effects.py``, ``bench/blind_effects_more.py``,
``bench/blind_effects_third.py`` ... ``bench/blind_effects_ninth.py``, ``bench/blind_effects_stamps.py``) names.

Same world and machinery as ``bench/blind_effects.py`` (imported: its plan, cache, DAQ frame and printed row): the
realistic world's co-simulation (``system_models/realistic_motor.toml``, the rig's 72-run plan at a 1 ms step, 1 mm/s
speed noise, 2 % run-to-run contact scatter). Each kind draws from one random stream of its seed. The kinds:

* ``bar_crown_track`` -- logged ``track_offset_mm`` per sample, a digital indicator on the stator holder's lateral
  slide (5 um of noise, 1 um resolution). To spread the lining's wear the operator moves the stator across the
  friction bar's width before each run, to a track offset ``y`` uniform in -1.5..+1.5 mm (a design factor). Lapping
  rolled the bar's top off toward its edges: across its width it is a crown of radius ``R`` (drawn in 60-100 mm)
  whose apex lies at ``y0`` (drawn in -0.3..+0.3 mm) from the indicator's zero. Off the apex the bar's surface lies
  lower by ``(y - y0)^2 / (2 R)`` (up to ~27 um), and the preload spring (the motor's own stiffness ``k_p``)
  extends by as much, so ``P0(y) = P0 - k_p (y - y0)^2 / (2 R)``: an even, quadratic law of the logged offset
  (never above P0, down to ~0.7 P0), not monotone in it. The tip's tilt on the crown (a few mrad) is left out.
* ``track_wipe_protocol`` -- no column; a state of the recording protocol. The lab's procedure has the operator
  wipe the friction bar's track with solvent every 8 traverses (before runs 1, 9, 17, ...). The wipe strips the
  bar's thin lubricant film, so the tip's slip friction is higher just after it, and each traverse redeposits a
  share of the film from the lining: ``mu_p (1 + W q^n)``, ``n`` the traverses since the last wipe (0 for the
  wiped run), ``W`` drawn in 0.12-0.20 and ``q`` in 0.40-0.60. The co-simulation holds ``mu_p`` per run, so the
  film's recovery is counted in whole traverses. A wipe takes the operator longer than the plan's pause: the rest
  before each wiped run after the first is drawn in 20-40 s (the session clock shows it; nothing else does).
* ``weight_touchdown`` -- no column; along the stroke, through the load. The loads are hooked brass cylinders of
  one diameter, so a weight's height grows with its mass, ``h_m |m|`` (``h_m`` drawn in 0.25-0.35 mm/g). The
  operator cut the load line with the empty hook hanging a clearance ``c`` (drawn in 4-8 mm) above the table at
  the stroke's end nearest the load's pulley (the -position end for a positive load, which pulls toward
  -position; the +position end for a negative one). Within ``x_td = h_m |m| - c`` of that end the weight rests on
  the table and pulls on nothing: the load's force and inertia vanish there (a hard table: a step in the load at
  the crossing). A run toward the pulley's end loses its load near its end; a run away from it starts unloaded
  and lifts the weight at the crossing. Heavier loads rest over more of the stroke (up to ~27 mm at 0.09 kg, none
  for a light weight when ``h_m |m| < c``).
* ``scope_scale_decoy`` -- a decoy, no effect on the motor: logged ``scope_scale_V_div`` per sample, the vertical
  scale (V per division at the probe's tip) of the oscilloscope that watches the drive, read by the DAQ program.
  At each new V0 setting the operator presses the scope's autoset, which picks the smallest scale of its 1-2-5
  series (50, 100, 200, 500 V/div) at which the drive's peak-to-peak ``2 V0`` spans at most ``D`` divisions (``D``
  drawn in 5.0-6.4, the autoset's fill): a coarse step function of the plan's V0 that acts on nothing. It must
  not be traced.

Pass rule (fixed before any loop ran; the eighth and ninth audits'): a kind passes when a regressor of ``WANT`` is
among the first two traced and ``a^2 <= b0^2 + (b^2 - b0^2) / 4``, with b and a the TEST free-run nrmse before and
after the loop and b0 the clean control's before at the same seed (``bench/blind_effects.py clean SEED``). The decoy
passes when ``scope_scale_V_div`` is nowhere in ``traced_all`` and ``a <= 1.02 b``. ``WANT``: the offset column
for the crown; for the wipe, a regressor of the session's clock or order or of the rests between runs (its name
holds ``pause``, ``rest``, ``gap``, ``time``, ``order``, ``index``, ``count`` or ``since``, and not
``time_in_run``: the run's own clock carries no state between runs); for the touchdown, a regressor of the position
(its name holds ``position``, alone or in an interaction with the load).

Usage: python bench/blind_effects_tenth.py KIND SEED [--cache DIR] [--report FILE]   (KIND: one of the above or
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

KINDS = ("bar_crown_track", "track_wipe_protocol", "weight_touchdown", "scope_scale_decoy")
#: the column each kind acts through (the decoy's: the column that must NOT be traced); None: none logged
CHANNEL = {"bar_crown_track": "track_offset_mm", "track_wipe_protocol": None, "weight_touchdown": None,
           "scope_scale_decoy": "scope_scale_V_div"}
#: the regressors accepted as the effect's when traced among the first two (fixed before any loop ran; for the
#: wipe a name holding ``time_in_run`` is not accepted)
WANT = {"bar_crown_track": ("track_offset_mm",),
        "track_wipe_protocol": ("pause", "rest", "gap", "time", "order", "index", "count", "since"),
        "weight_touchdown": ("position",),
        "scope_scale_decoy": ()}
WIPE_EVERY = 8                          # traverses between the procedure's wipes
SCOPE_SCALES_V_DIV = (50.0, 100.0, 200.0, 500.0)


def draw(kind: str, seed: int, n_runs: int) -> dict:
    """The kind's parameters and per-run values (its own random stream of ``seed``)."""
    rng = np.random.default_rng([seed, 121, KINDS.index(kind) if kind in KINDS else 99])
    if kind == "bar_crown_track":
        return {"R_m": float(rng.uniform(0.06, 0.10)), "y0_m": float(rng.uniform(-0.3e-3, 0.3e-3)),
                "y_m": rng.uniform(-1.5e-3, 1.5e-3, n_runs)}
    if kind == "track_wipe_protocol":
        return {"W": float(rng.uniform(0.12, 0.20)), "q": float(rng.uniform(0.40, 0.60)),
                "wipe_pause_s": rng.uniform(20.0, 40.0, n_runs)}
    if kind == "weight_touchdown":
        return {"h_m_per_kg": float(rng.uniform(0.25, 0.35)), "c_m": float(rng.uniform(4e-3, 8e-3))}
    if kind == "scope_scale_decoy":
        return {"D_div": float(rng.uniform(5.0, 6.4))}
    return {}


def crowned_preload_N(P0_N, k_p_N_per_m: float, y_m, y0_m: float, R_m: float):
    """The preload [N] on the track ``y_m`` [m] of a bar crowned with radius ``R_m`` [m] about ``y0_m`` [m]:
    ``P0 - k_p (y - y0)^2 / (2 R)``."""
    drop = (np.asarray(y_m, float) - y0_m) ** 2 / (2.0 * R_m)
    return np.asarray(P0_N, float) - k_p_N_per_m * drop


def wipe_counts(n_runs: int, every: int = WIPE_EVERY):
    """Each run's traverses since the last wipe (wipes before runs 1, 1 + every, ...): ``k mod every``."""
    return np.arange(n_runs) % every


def wipe_factor(n, W: float, q: float):
    """The slip friction's factor ``n`` traverses after a wipe: ``1 + W q^n``."""
    return 1.0 + W * np.power(q, np.asarray(n, float))


def run_pauses_s(n_runs: int, pause_s: float, wipe_pause_s, every: int = WIPE_EVERY):
    """The rest [s] before each run after the first (``n_runs - 1`` values): ``wipe_pause_s[k]`` before a wiped run
    ``k`` (``k mod every == 0``), else the plan's ``pause_s``."""
    k = np.arange(1, n_runs)
    return np.where(k % every == 0, np.asarray(wipe_pause_s, float)[k], pause_s)


def touchdown_zone_m(load_kg, h_m_per_kg: float, c_m: float):
    """The length [m] of the stroke's end (nearest the load's pulley) where the weight rests: ``max(0, h_m |m| -
    c)`` (0 for no load)."""
    return np.maximum(0.0, h_m_per_kg * np.abs(np.asarray(load_kg, float)) - c_m)


def weight_rests(s_m, load_kg: float, zone_m: float, s_min_m: float, s_max_m: float):
    """Whether the weight rests on the table at the slider's positions ``s_m`` [m]: within ``zone_m`` of the
    -position end for a positive load, of the +position end for a negative one; never without a load."""
    s = np.asarray(s_m, float)
    if load_kg == 0 or zone_m <= 0:
        return np.zeros(s.shape, bool)
    x_end = s - s_min_m if load_kg > 0 else s_max_m - s
    return x_end < zone_m


def scope_scale_V_div(V0_V, D_div: float, scales=SCOPE_SCALES_V_DIV):
    """The autoset's scale [V/div] for the amplitude ``V0_V`` [V]: the smallest of ``scales`` with ``2 V0 / scale
    <= D_div``."""
    V = np.atleast_1d(np.asarray(V0_V, float))
    out = np.array([next((s for s in scales if 2.0 * v / s <= D_div), scales[-1]) for v in V])
    return out if np.ndim(V0_V) else float(out[0])


def traverse_load(mp, nominal, plan, V0, d, m_load):
    """One traverse in the direction ``d`` at ``V0`` [V] with the load ``m_load`` (a constant or a function of the
    run's time) [kg]; the operator's supply is set at 25 degC and the plan's frequency."""
    V_s = float(drv.supply_for_voltage_V(nominal.driver, V0, 1.0, plan.f_drive_Hz, plan.ambient_degC))
    s0 = mp.slider.s_min_m if d > 0 else mp.slider.s_max_m
    m = InProcessMotor(mp, h_s=plan.step_s)
    m.initialize(V_s=V_s, f_s=plan.f_drive_Hz, T=plan.ambient_degC, direction=d, m_load=m_load, s0=s0)
    rec = ("Slider.s", "Stator.T_stator")
    return m.run(plan.max_run_s, record=rec, until=lambda mm: mm.value("Slider.at_stop") == d)


def traverse_touchdown(mp, nominal, plan, V0, L, d, zone_m: float):
    """``(record, t_cross)``: one traverse whose weight rests within ``zone_m`` of its pulley's end. The motion is
    monotone, so a first pass with the load of the run's start finds the time the slider crosses the zone's edge,
    and a second pass steps the load there (None: no crossing, the first pass stands)."""
    sl = mp.slider
    s0 = sl.s_min_m if d > 0 else sl.s_max_m
    rest0 = bool(weight_rests([s0], L, zone_m, sl.s_min_m, sl.s_max_m)[0])
    m_first, m_then = (0.0, L) if rest0 else (L, 0.0)
    r = traverse_load(mp, nominal, plan, V0, d, m_first)
    rests = weight_rests(r["Slider.s"], L, zone_m, sl.s_min_m, sl.s_max_m)
    flip = np.flatnonzero(rests != rest0)
    if m_first == m_then or flip.size == 0:
        return r, None
    t_c = float(r["time"][flip[0]])
    load = lambda t, t_c=t_c: m_first if t < t_c - 1e-12 else m_then  # noqa: E731
    return traverse_load(mp, nominal, plan, V0, d, load), t_c


def experiment(kind: str, seed: int):
    """The 72-run experiment of one kind and its truth."""
    plan, nominal, conds, factors, p, every = be.setting(kind, seed, draw)
    frames, per_run, t_next = [], [], 0.0
    n_runs = len(conds)
    counts = wipe_counts(n_runs)
    pauses = run_pauses_s(n_runs, plan.pause_s, p["wipe_pause_s"]) if kind == "track_wipe_protocol" else None
    for k, (V, L, d) in enumerate(conds):
        mp = scattered_motor(nominal, factors[k])
        t_cross, zone = None, None
        if kind == "bar_crown_track":
            mp = mp.replace(stator__P0_N=float(crowned_preload_N(
                mp.stator.P0_N, mp.stator.preload_stiffness_N_per_m, p["y_m"][k], p["y0_m"], p["R_m"])))
        elif kind == "track_wipe_protocol":
            mp = mp.replace(interface__mu_p=mp.interface.mu_p * float(wipe_factor(counts[k], p["W"], p["q"])))
        if kind == "weight_touchdown":
            zone = float(touchdown_zone_m(L, p["h_m_per_kg"], p["c_m"]))
            r, t_cross = traverse_touchdown(mp, nominal, plan, V, L, d, zone)
        else:
            r = be.traverse(mp, nominal, plan, V, L, d)
        idx = np.arange(0, len(r["time"]), every)
        t, s = r["time"][idx], r["Slider.s"][idx]
        extra = {}
        noise = np.random.default_rng([seed, 122, k]).standard_normal(len(t))
        if kind == "bar_crown_track":
            extra["track_offset_mm"] = np.round(p["y_m"][k] * 1e3 + 0.005 * noise, 3)
        elif kind == "scope_scale_decoy":
            extra["scope_scale_V_div"] = np.full(len(t), scope_scale_V_div(V, p["D_div"]))
        out = be.daq_frame(plan, t_next, k, t, s, V, L, d, **extra)
        frames.append(out)
        per_run.append({"run": k + 1, "P0_N": mp.stator.P0_N, "mu_p": mp.interface.mu_p,
                        "touchdown_zone_m": zone, "t_cross_s": t_cross})
        pause = plan.pause_s if pauses is None or k + 1 >= n_runs else float(pauses[k])
        t_next = float(out[dataio.TIME].iloc[-1]) + pause
    return be.finish(kind, frames, per_run, p, nominal, plan)


def main(argv=None):
    be.run_cli(argv, __doc__, KINDS, experiment, be.want_fields(CHANNEL, WANT))


if __name__ == "__main__":
    main()
