"""Command line: ``l1b2 <command> ...`` (``l1b2 --help``).

Every user error ends with one line ``l1b2: error: ...`` on stderr and a
non-zero exit status, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from . import __version__
from .cluster import default_workers
from .errors import L1B2Error
from .console import StageBar, pct, print_input_checks, stage_lines


def _floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got '{text}'") from None


def _motor(args):
    from .physics.params import load_motor, motor_file
    if getattr(args, "motor", None) and getattr(args, "params", None):
        raise L1B2Error("give either --motor NAME or --params FILE, not both")
    if getattr(args, "motor", None):
        return load_motor(motor_file(args.motor))
    return load_motor(getattr(args, "params", None))


# ---------------------------------------------------------------------------
# commands
# ---------------------------------------------------------------------------

def cmd_fmus(args) -> int:
    from .fmi.build import SUBSYSTEM_FMUS, build_fmu
    mp = _motor(args)
    for name in args.names or SUBSYSTEM_FMUS:
        print(build_fmu(name, args.out, mp=mp))
    return 0


def cmd_simulate(args) -> int:
    """One run of the coupled motor; CSV with units in the header."""
    import numpy as np

    from .cosim.engine import InProcessMotor
    from .cosim.master import CoSimulation
    from .cosim.ssp import COMPONENT_PARAMS
    from .fmi.cache import ensure_fmus
    from .physics import driver as drv

    mp = _motor(args)
    if args.direction not in (1, -1):
        raise L1B2Error(f"--direction must be 1 or -1, got {args.direction}")
    s0 = args.s0 if args.s0 is not None else (mp.slider.s_min_m if args.direction > 0 else mp.slider.s_max_m)
    V_s = float(drv.supply_for_voltage_V(mp.driver, args.V0, 1.0, args.frequency, args.temperature))
    inputs = dict(V_s=V_s, duty=1.0, f_s=args.frequency, T=args.temperature, direction=float(args.direction),
                  m_load=args.load)
    stop = (lambda v: v["Slider.at_stop"] == args.direction) if not args.full else None
    if args.engine == "fmu":
        from dataclasses import asdict
        overrides = {f"{c}.{k}": v for c, a in COMPONENT_PARAMS.items() for k, v in asdict(getattr(mp, a)).items()}
        if args.pure_slip:
            overrides["Interface.pure_slip"] = True
        fmu_dir = args.fmu_dir or ensure_fmus()
        with CoSimulation(fmu_dir=fmu_dir, step_s=args.step, parameters=overrides,
                          iterate=args.iterate) as cs:
            res = cs.run(args.duration, inputs, start_values={"Slider.s0": s0, "Stator.s": s0},
                         stop_when=stop)
    else:
        from .cosim.engine import RECORDED
        m = InProcessMotor(mp, h_s=args.step, pure_slip=args.pure_slip)
        m.initialize(s0=s0, **inputs)
        rec = RECORDED + ("Slider.at_stop",)
        res = m.run(args.duration, record=rec,
                    until=(lambda mm: mm.value("Slider.at_stop") == args.direction) if not args.full else None)
    path = res.to_csv(args.out)
    if args.plot:
        res.plot(columns=("Slider.v", "Slider.s", "Stator.U_w"), path=args.plot,
                 title=f"l1b2 simulate ({args.engine}): V0 {args.V0:g} V, load {args.load:+g} kg, "
                       f"direction {args.direction:+d}, step {args.step * 1e3:g} ms")
    v = res.df["Slider.v"].to_numpy()
    print(f"wrote {path}: {len(v)} samples, {res.df['time'].iloc[-1]:.4g} s, peak speed {np.max(np.abs(v)) * 1e3:.1f} mm/s")
    return 0


def cmd_rig(args) -> int:
    """The paper's whole experiment on the co-simulated motor."""
    from .data import plots
    from .rig.experiment import (
        RigPlan,
        parse_injection,
        run_experiment,
        write_experiment,
    )

    from .jsonio import dumps
    from .workflows import output_dir

    mp = _motor(args)
    plan = RigPlan(voltages_V=args.voltages, loads_kg=args.loads, step_s=args.step, seed=args.seed,
                   sample_rate_Hz=args.sample_rate,
                   record_temperature=args.record_temperature, pause_s=args.pause, max_run_s=args.max_run,
                   speed_noise_m_s=args.speed_noise, run_scatter=args.run_scatter,
                   frequencies_Hz=tuple(args.frequencies or ()), frequency_jitter_Hz=args.frequency_jitter)
    injections = [parse_injection(s) for s in args.inject]
    if args.jobs is not None:
        print("l1b2: warning: --jobs is deprecated, use --workers", file=sys.stderr)
    workers = args.jobs if args.jobs is not None else args.workers
    out = Path(args.out)
    with output_dir(out, command="rig") as tmp:
        t0 = time.perf_counter()
        df, truth = run_experiment(plan, mp, injections=injections, engine=args.engine, workers=workers,
                                   scheduler=args.scheduler, fmu_dir=args.fmu_dir,
                                   injection_seed=args.injection_seed, progress=not args.quiet)
        truth["wall_time_s"] = round(time.perf_counter() - t0, 2)
        paths = write_experiment(df, tmp, mp, plan, truth)
        summary = {"runs": int(df["run"].nunique()), "samples": int(len(df)), "wall_time_s": truth["wall_time_s"],
                   "files": {k: str(out / Path(v).name) for k, v in paths.items()}}
        if not args.no_plots:
            plots.fig9a_speed_vs_position_by_voltage(df, tmp / "fig9a_speed_vs_position_by_voltage.png")
            plots.fig9b_speed_vs_position_by_load(df, tmp / "fig9b_speed_vs_position_by_load.png")
            _, fit = plots.fig9c_speed_vs_tip_velocity(df, tmp / "fig9c_speed_vs_tip_velocity.png")
            summary["fig9c"] = fit
        (tmp / "rig_summary.json").write_text(dumps(summary, digits=12))
    print(f"rig: {summary['runs']} runs, {summary['samples']} samples in {summary['wall_time_s']} s -> {out}")
    if "fig9c" in summary:
        print(f"fig9c: v_s = {summary['fig9c']['k0']:.3f} * omega*U_w + {summary['fig9c']['intercept_m_s'] * 1e3:.1f} mm/s,"
              f" R^2 = {summary['fig9c']['r2']:.3f}")
    return 0


def cmd_sweep(args) -> int:
    """A design study: operating-point grid x Monte-Carlo / Saltelli draws of motor parameters, on Dask."""
    from .workflows import run_sweep
    try:
        res = run_sweep(args.spec, args.out, workers=args.workers, scheduler=args.scheduler,
                        progress=not args.quiet, plots_on=not args.no_plots, max_runs=args.max_runs)
    except KeyboardInterrupt:
        print(f"l1b2: interrupted; finished chunks are in {Path(args.out) / 'chunks'}: run the same command "
              f"to resume", file=sys.stderr)
        return 130
    i = res.info
    print(f"sweep: {len(res.table)} samples ({i['executed_samples']} run, {i['skipped_samples']} already stored), "
          f"{len(res.failed)} failed, {i['wall_time_s']} s on {i['engine_workers']} worker(s)"
          + (f", {i['worker_seconds_per_traverse']} worker-s per traverse" if i['worker_seconds_per_traverse'] else ""))
    for line in res.report_lines():
        print(line)
    print(f"wrote {Path(args.out) / 'samples.parquet'}, summary.csv, sensitivity.csv, study.json")
    for f in sorted(Path(args.out).glob("sweep_*.png")):
        print(f"plot: {f}")
    return 0


def _add_sweep_parser(sub):
    p = sub.add_parser("sweep", help="design study: operating points x parameter draws on Dask (Parquet, "
                                     "percentiles, sensitivities, PNGs)")
    p.add_argument("--spec", type=Path, required=True, help="study specification (TOML; see the docs' how-to 'Design study')")
    p.add_argument("--out", type=Path, required=True, help="output folder (rerun the same command to resume)")
    _engine_args(p, default_workers=default_workers(), what="traverses (0 = serially in this process)")
    p.add_argument("--no-plots", action="store_true", help="write no PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--max-runs", type=int, default=None, metavar="N",
                   help="refuse a study of more than N runs (samples x operating points; default 100000)")
    p.set_defaults(func=cmd_sweep)


def cmd_study(args) -> int:
    """A multi-seed study on the virtual rig: parameter coverage or the close loop's control."""
    from .study.world import World
    from .workflows import run_study
    world = World(motor=args.world)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    from .jsonio import dumps
    say = None if args.quiet else (lambda row: print(f"row {dumps(row, indent=None)}", flush=True))
    from .study.recovery import FitSettings
    res = run_study(args.study, args.out, seeds, world=world, fit=FitSettings(n_starts=args.starts, model=args.model),
                    injections=[s for s in args.injections.split(",") if s] if args.injections else None,
                    workers=args.workers, scheduler=args.scheduler, clean_fit=not args.no_clean_fit,
                    loop_settings={"baseline": args.baseline} if args.baseline else None,
                    plots_on=not args.no_plots, progress=say)
    for line in res.report_lines():
        print(line)
    print(f"wrote {Path(args.out) / 'study.json'}, rows.csv ({res.info['tasks']} tasks, {res.info['wall_time_s']} s "
          f"on {res.info['workers']} worker(s))")
    return 0


def _add_study_parser(sub) -> None:
    p = sub.add_parser("study", help="multi-seed study on the virtual rig: 95 %% interval coverage of injected "
                                     "parameters, or the close loop's control (Dask)")
    p.add_argument("study", choices=("coverage", "control"),
                   help="coverage: 95 %% intervals of injected physical parameters against their true values; "
                        "control: the close loop on data without an injected effect")
    p.add_argument("--out", type=Path, required=True, help="output folder (study.json, rows.csv, PNG)")
    p.add_argument("--seeds", type=int, default=20, help="number of seeds")
    p.add_argument("--first-seed", type=int, default=0, help="first seed")
    p.add_argument("--world", choices=("realistic", "reference"), default="realistic",
                   help="the rig's motor (both with 1 mm/s speed noise and 2 %% run-to-run contact scatter)")
    p.add_argument("--injections", default="", help="coverage: comma-separated injections (default: every one "
                   "whose family has a physical parameter)")
    p.add_argument("--starts", type=int, default=4, help="coverage: starts of the identification's global search "
                   "(the close loop's baseline uses 4)")
    p.add_argument("--model", choices=("eq29", "pure_slip"), default="eq29",
                   help="coverage: the predictor family of the fits (the close loop's default baseline: eq29)")
    p.add_argument("--no-clean-fit", action="store_true",
                   help="coverage: skip the fit of the same seed without the injection (the bias diagnosis)")
    p.add_argument("--baseline", choices=DRIVE_LAWS + ("best",), default=None,
                   help="control: the close loop's baseline family (default: the close loop's, eq29)")
    _engine_args(p, default_workers=2, what="seeds (0 = serially in this process)")
    p.add_argument("--no-plots", action="store_true", help="write no PNG figure")
    p.add_argument("--quiet", action="store_true", help="no line per finished seed")
    p.set_defaults(func=cmd_study)


def _engine_args(p, default_workers, what):
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=default_workers,
                   help=f"local Dask worker processes (one thread each) for the {what}")
    g.add_argument("--scheduler", metavar="ADDRESS", help="use the Dask cluster at ADDRESS (tcp://host:8786) "
                   "instead of a local one")


# ---------------------------------------------------------------------------
# parser
# ---------------------------------------------------------------------------

def _motor_args(p) -> None:
    p.add_argument("--params", type=Path, help="motor parameter TOML (default: reference motor)")
    p.add_argument("--motor", help="an embedded motor by name: reference_motor (default), realistic_motor "
                   "(Coulomb-dominated friction, where Eq. 29 is not exact)")


UNUSUAL_UNITS_HELP = ("accept values a linear USM rig does not produce in SI units (grams as kg, kV, ms, a speed "
                      "column disagreeing with the position's derivative, ...) instead of refusing them as a likely "
                      "unit mistake; recorded in the report")


NOISE_FITS = ("auto", "alternate", "profile")
#: the predictor families (:data:`l1b2.predictor.model.DRIVE_LAWS`, repeated so that parsing imports no numpy)
DRIVE_LAWS = ("eq29", "pure_slip")
NOISE_FIT_HELP = ("'alternate': least squares at fixed noise variances, re-estimated alternately; 'profile': "
                  "profile-likelihood search (faster, reached the reference optimum on the 20 000-sample benchmark "
                  "where the alternation stopped 5 log-likelihood units short, but ended in a worse optimum with a "
                  "confounded extra force); 'auto': profile for the Eq. 29 model alone, alternate with extra forces")
#: the fold schemes of the session-clock candidates (:data:`l1b2.closeloop.folds.CLOCK_FOLDS`'s keys)
CLOCK_FOLDS = ("blocks", "rotation")
#: the fold units of the other candidates (:data:`l1b2.closeloop.folds.UNIT_FOLDS`'s keys)
FOLD_UNITS = ("run", "condition")
NOISES = ("common", "per_run")
NOISE_HELP = ("noise variances of Eq. 32: 'common' (default, the paper's single R) or 'per_run' (one per run; on "
              "data the model does not fit exactly its likelihood is multimodal and its optima predicted held-out "
              "runs worse in every case measured)")


def _close_loop_args(p: argparse.ArgumentParser) -> None:
    """The close-loop command's settings (the :class:`l1b2.closeloop.loop.CloseLoop` rules)."""
    p.add_argument("--order", type=int, default=8, help="polynomial order of A, B, P in position (paper: 8)")
    p.add_argument("--folds", type=int, default=5, help="cross-validation folds over runs")
    p.add_argument("--alpha", type=float, default=0.01, help="significance level (Bonferroni over effects)")
    p.add_argument("--min-gain", type=float, default=0.05, help="smallest linearised held-out share of the "
                   "residual for a candidate to be shortlisted (refit and cross-validated)")
    p.add_argument("--min-cv-gain", type=float, default=0.03, help="smallest relative fall of the cross-validated "
                   "free-run error (re-identified model, folds over runs) for an effect to be added")
    p.add_argument("--min-cv-drop", type=float, default=0.005, help="smallest absolute fall of the cross-validated "
                   "free-run nrmse (share of the speed's rms; 0.005 = 0.5 percentage points) for a structural term "
                   "(one relaxing Eq. 29's linearisation) to be added: the materiality threshold (0 reports every "
                   "structural term that helps)")
    p.add_argument("--screen-alpha", type=float, default=0.01, help="when no candidate passes the Bonferroni-"
                   "corrected screen, the best one with a run-level p-value below this (uncorrected) level, e.g. "
                   "0.01, is still refit and cross-validated (finds drifts in time); 0: off")
    p.add_argument("--max-rounds", type=int, default=3, help="most effects added, one per round")
    p.add_argument("--response-column", action="append", dest="response_columns", metavar="NAME",
                   help="a logged column that is a measured response of the motor, never offered as a cause "
                   "(repeatable; replaces the default list, tip_velocity_amp_m_s, and the consequence test)")
    p.add_argument("--no-response-columns", action="store_true", help="every logged column is a candidate cause: "
                   "no default response list and no consequence test")
    p.add_argument("--noise-fit", choices=NOISE_FITS, default="alternate",
                   help="the baseline identification's search: " + NOISE_FIT_HELP + " (alternate is the search with "
                   "which the close loop was measured)")
    p.add_argument("--noise", choices=NOISES, default="common", help=NOISE_HELP)
    p.add_argument("--baseline", choices=DRIVE_LAWS + ("best",), default="eq29",
                   help="the predictor family the loop starts from: eq29 (default), pure_slip, or best (Eq. 29 "
                   "unless the pure-slip family's cross-validated free-run error on TRAIN is lower by the "
                   "materiality threshold --min-cv-drop; both reported)")
    p.add_argument("--clock-folds", metavar="{blocks,rotation}", default="blocks", help="folds of the candidates "
                   "that depend on the session clock: blocks (contiguous stretches of the session) or rotation "
                   "(whole conditions dealt to the folds in turn)")
    p.add_argument("--fold-unit", metavar="{run,condition}", default="run", help="folds of the other candidates: "
                   "run (runs dealt to the folds) or condition (whole conditions, a drive amplitude and a load with "
                   "all their runs, dealt to the folds)")
    p.add_argument("--refit-repeats", metavar="N", default="1", help="splits of TRAIN's runs into the refit's "
                   "folds for a round's acceptance (each run held out N times; N times the refits)")
    p.add_argument("--tie-repeats", metavar="N", default="3", help="splits over which a round with a tied fold "
                   "vote is cross-validated again (not above --refit-repeats: off)")
    p.add_argument("--seed", type=int, default=0, help="seed of the multi-start and of the fold assignment")
    p.add_argument("--slider-mass", type=float, help="slider mass [kg] (overrides the sidecars)")
    p.add_argument("--allow-unusual-units", action="store_true", help=UNUSUAL_UNITS_HELP)
    p.add_argument("--no-plots", action="store_true", help="write no PNG figures")
    p.add_argument("--quiet", action="store_true", help="no stage lines and no progress bars")


def _add_rig_parser(sub) -> None:
    """The ``rig`` subcommand's options."""
    p = sub.add_parser("rig", help="the paper's experiment on the virtual rig (data-format CSVs + Fig. 9 plots)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--voltages", type=_floats, default=(220.0, 255.0, 290.0, 324.0), help="V0 levels [V]")
    p.add_argument("--loads", type=_floats, default=(-0.09, -0.07, -0.05, -0.03, 0.0, 0.03, 0.05, 0.07, 0.09),
                   help="signed loads [kg]")
    p.add_argument("--engine", choices=("fmu", "inprocess"), default="fmu",
                   help="'fmu': the four FMUs through fmpy; 'inprocess': the same blocks without FMI (faster)")
    p.add_argument("--fmu-dir", type=Path, help="folder with the subsystem FMUs (default: built once into the "
                   "per-user cache)")
    _engine_args(p, default_workers=2, what="runs (stateful effects run serially; 1 = serially here)")
    p.add_argument("--jobs", type=int, help="deprecated alias of --workers")
    p.add_argument("--step", type=float, default=2e-4, help="communication step [s]")
    p.add_argument("--sample-rate", type=float, default=1000.0, metavar="HZ",
                   help="the DAQ's sampling rate [Hz] (default 1000; the step must divide its period)")
    p.add_argument("--pause", type=float, default=1.0, help="pause between runs [s]")
    p.add_argument("--max-run", type=float, default=4.0, help="longest run [s]")
    p.add_argument("--seed", type=int, default=0, help="seed of the run order, the speed noise and the run scatter")
    p.add_argument("--speed-noise", type=float, default=0.0, metavar="M_PER_S",
                   help="std of white noise on the speed channel [m/s] (default 0)")
    p.add_argument("--run-scatter", type=float, default=0.0, metavar="REL",
                   help="relative std of the contact's preload and friction coefficient from run to run "
                        "(default 0; 0.02 is a 2 %% scatter)")
    p.add_argument("--inject", action="append", default=[], metavar="EFFECT[:Comp.param=value,...]",
                   help="switch on an undeclared physical effect (repeatable); see `l1b2 injections`")
    p.add_argument("--injection-seed", "--effect-seed", dest="injection_seed", type=int,
                   help="draw the injections' sizes at random with this seed")
    p.add_argument("--record-temperature", action="store_true", help="write the stator temperature column")
    p.add_argument("--frequencies", type=_floats, metavar="HZ,HZ,...",
                   help="drive frequencies [Hz] the (V0, load) conditions take in turn (default: one, 48.5 kHz)")
    p.add_argument("--frequency-jitter", type=float, default=0.0, metavar="HZ",
                   help="half-width of a uniform per-run frequency offset [Hz] (a drive that tracks resonance)")
    p.add_argument("--no-plots", action="store_true", help="write no PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _motor_args(p)
    p.set_defaults(func=cmd_rig)


class DefaultsFormatter(argparse.HelpFormatter):
    """Help with every option's default (unless it has none, or the help already says it)."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if (action.option_strings and default is not None and default is not False and default != []
                and default is not argparse.SUPPRESS and "default" not in text):
            shown = ",".join(f"{x:g}" for x in default) if isinstance(default, tuple) else default
            text += f" (default: {shown})"
        return text


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="l1b2", description="L1B2 linear ultrasonic motor: FMUs, co-simulation, "
                                                            "virtual rig, identification")
    ap.add_argument("--version", action="version", version=f"l1b2 {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("fmus", help="build the subsystem FMUs")
    p.add_argument("names", nargs="*", help="Driver Stator Interface Slider (default: all)")
    p.add_argument("--out", type=Path, default=Path("dist/fmus"), help="output folder")
    _motor_args(p)
    p.set_defaults(func=cmd_fmus)

    p = sub.add_parser("simulate", help="one run of the coupled motor, CSV out")
    p.add_argument("--V0", type=float, default=324.0, help="stator voltage amplitude [V]")
    p.add_argument("--load", type=float, default=0.0, help="signed load [kg], > 0 pulls toward -position")
    p.add_argument("--direction", type=int, default=1, help="+1 (CH1) or -1 (CH2)")
    p.add_argument("--frequency", type=float, default=48500.0, help="drive frequency [Hz]")
    p.add_argument("--temperature", type=float, default=25.0, help="ambient temperature [degC]")
    p.add_argument("--duration", type=float, default=2.0, help="longest simulated time [s]")
    p.add_argument("--full", action="store_true", help="do not stop at the far end stop")
    p.add_argument("--s0", type=float, help="start position [m] (default: the end stop behind)")
    p.add_argument("--step", type=float, default=2e-4, help="communication step [s]")
    p.add_argument("--engine", choices=("fmu", "inprocess"), default="fmu",
                   help="'fmu': the four FMUs through fmpy; 'inprocess': the same blocks without FMI (faster)")
    p.add_argument("--fmu-dir", type=Path, help="folder with the subsystem FMUs (default: built once into the "
                   "per-user cache)")
    p.add_argument("--iterate", action="store_true", help="fixed-point iteration of each macro step")
    p.add_argument("--pure-slip", action="store_true", help="interface in the paper's pure-slip mode")
    _motor_args(p)
    p.add_argument("--out", type=Path, required=True, help="CSV file")
    p.add_argument("--plot", type=Path, help="PNG of speed, position and tip amplitude")
    p.set_defaults(func=cmd_simulate)

    _add_rig_parser(sub)

    _add_sweep_parser(sub)
    p = sub.add_parser("demo", help="the main job end to end on the reference motor and the virtual rig")
    p.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder")
    p.add_argument("--effect", default="pulley_friction", help="effect injected for the close-the-loop stage "
                   "(`l1b2 injections` lists them)")
    p.add_argument("--engine", choices=("fmu", "inprocess"), default="fmu",
                   help="'fmu': the rig runs the four FMUs through fmpy; 'inprocess': the same blocks without FMI")
    p.add_argument("--jobs", type=int, default=2, help="parallel rig runs (Dask worker processes)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    _motor_args(p)
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("identify", help="identify the Eq. 29 predictor from measured data (max. likelihood)")
    p.add_argument("--train", type=Path, required=True, help="measured data (CSV in the rig data format)")
    p.add_argument("--test", type=Path, help="held-out data (default: the paper's split of TRAIN by load)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--test-loads", type=_floats, default=(0.05,), help="|load| [kg] held out when --test is absent")
    p.add_argument("--order", type=int, default=8, help="polynomial order of A, B, P (paper: 8)")
    p.add_argument("--criterion", choices=("free_run", "one_step"), default="free_run",
                   help="what the likelihood scores: the free-run or the one-step prediction")
    p.add_argument("--fix", default=None, help="'none' (the paper's full set; the default), 'recommended' (pins "
                                                "sigma, k0, mu, mu_sd: predictions unchanged) or name=value,...")
    p.add_argument("--starts", type=int, default=8, help="multi-start local searches")
    p.add_argument("--model", choices=DRIVE_LAWS, default="eq29", help="the predictor family: eq29 (the paper's) "
                   "or pure_slip (the slip ratio follows the speed; 'recommended' then pins k0, mu, mu_sd)")
    p.add_argument("--noise-fit", choices=NOISE_FITS, default="auto", help=NOISE_FIT_HELP)
    p.add_argument("--noise", choices=NOISES, default="common", help=NOISE_HELP)
    p.add_argument("--seed", type=int, default=0, help="seed of the multi-start's start points")
    p.add_argument("--slider-mass", type=float, help="slider mass [kg] (overrides the sidecar)")
    p.add_argument("--allow-unusual-units", action="store_true", help=UNUSUAL_UNITS_HELP)
    p.add_argument("--no-plots", action="store_true", help="write no PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--verbose", action="store_true", help="print every local search and the full fit report "
                   "(with the unidentifiable directions' tables)")
    p.set_defaults(func=cmd_identify)

    p = sub.add_parser("compare", help="predictor vs the co-simulation's steady states (derived and identified)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--identification", type=Path, help="identification.json from `l1b2 identify`")
    p.add_argument("--order", type=int, default=8, help="polynomial order of the derived predictor")
    _motor_args(p)
    p.set_defaults(func=cmd_compare)

    _add_frequency_map_parser(sub)

    p = sub.add_parser("close-loop", help="find the missing effect in the residual, add it, report before/after")
    p.add_argument("--train", type=Path, required=True, help="measured data to fit and diagnose on")
    p.add_argument("--test", type=Path, help="held-out data, only for the before/after report (default: the "
                                              "paper's split of TRAIN by load)")
    p.add_argument("--test-loads", type=_floats, default=(0.05,), help="|load| [kg] held out when --test is absent")
    p.add_argument("--out", "--report-dir", dest="out", type=Path, required=True,
                   help="output folder: report.json, report.md, PNGs (--report-dir is the former name)")
    p.add_argument("--export", type=Path, metavar="DIR",
                   help="also write DIR/fmus/Predictor.fmu carrying the final extended model, and "
                        "DIR/calibrated_manifest.json (which effect went where); effects with a physical home "
                        "are also carried into DIR/L1B2Motor_calibrated.ssp of the motor (--motor/--params)")
    _motor_args(p)
    _close_loop_args(p)
    _engine_args(p, default_workers=default_workers(), what="cross-validated refits (0 or 1 = serially in this "
                                                            "process)")
    p.set_defaults(func=cmd_close_loop)

    p = sub.add_parser("export", help="FMUs, L1B2Motor.ssp and L1B2Motor.fmu for other simulators")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--identification", type=Path, help="identification.json whose predictor Predictor.fmu carries "
                   "(default: the predictor derived from the motor's physics)")
    p.add_argument("--no-predictor", action="store_true", help="skip Predictor.fmu")
    p.add_argument("--from-report", type=Path, metavar="REPORT_DIR",
                   help="instead: Predictor.fmu carrying the calibrated extended model of a close-loop report "
                        "(REPORT_DIR/report.json), with calibrated_manifest.json")
    _motor_args(p)
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("injections", aliases=["effects"], help="list the effects the rig can inject")
    p.set_defaults(func=cmd_injections)
    _add_study_parser(sub)
    for parser in sub.choices.values():
        parser.formatter_class = DefaultsFormatter
    return ap


def _fmu_smoke(fmu_dir: Path, mp) -> list[tuple[str, str, float, str]]:
    """Run each subsystem FMU alone through fmpy on the reference motor; (fmu, output, value, unit)."""
    from fmpy import simulate_fmu

    op = mp.operating
    out = []
    r = simulate_fmu(str(fmu_dir / "Driver.fmu"), stop_time=1e-3, step_size=2e-4,
                     start_values={"V_s": op.V_s_V, "duty": op.duty, "f_s": op.f_drive_Hz, "T": op.T_degC})
    V0 = float(r["V0"][-1])
    out.append(("Driver", "V0", V0, "V"))
    r = simulate_fmu(str(fmu_dir / "Stator.fmu"), stop_time=5e-3, step_size=2e-4,
                     start_values={"V0": V0, "omega": 2 * 3.141592653589793 * op.f_drive_Hz})
    out += [("Stator", "U_l (free)", float(r["U_l"][-1]), "m"), ("Stator", "U_w (free)", float(r["U_w"][-1]), "m")]
    r = simulate_fmu(str(fmu_dir / "Interface.fmu"), stop_time=4e-4, step_size=2e-4,
                     start_values={"U_l": 1.2e-6, "U_w": 1.4e-6, "delta": -1.7, "v": 0.2, "F_p": 6.0})
    out.append(("Interface", "F_d", float(r["F_d"][-1]), "N"))
    r = simulate_fmu(str(fmu_dir / "Slider.fmu"), stop_time=0.05, step_size=2e-4,
                     start_values={"F_d": 1.0, "F_p": 6.0, "s0": -0.02})
    out.append(("Slider", "v after 50 ms at F_d = 1 N", float(r["v"][-1]), "m/s"))
    return out


def cmd_demo(args) -> int:
    """The main job end to end on the embedded default: reference motor, virtual rig."""
    from .fmi.build import build_subsystem_fmus
    mp = _motor(args)
    out = Path(args.out)
    fmu_dir = out / "fmus"
    print(f"[1] building the subsystem FMUs into {fmu_dir}")
    paths = build_subsystem_fmus(fmu_dir, mp)
    from fmpy.validation import validate_fmu
    for name, p in paths.items():
        problems = validate_fmu(str(p))
        print(f"    {name:9s} {p}  fmpy validation: {'no problems' if not problems else problems}")
    print("[2] each FMU alone through fmpy on the reference motor")
    for fmu, name, value, unit in _fmu_smoke(fmu_dir, mp):
        print(f"    {fmu:9s} {name:28s} {value:12.5g} {unit}")
    print(f"[3] the paper's experiment on the virtual rig, four FMUs co-simulated by fmpy (engine {args.engine})")
    rig_args = ["rig", "--out", str(out / "rig"), "--engine", args.engine, "--fmu-dir", str(fmu_dir),
                "--workers", str(args.jobs)] + (["--quiet"] if args.quiet else [])
    code = main(rig_args)
    if code:
        return code
    rig = out / "rig"
    print("[4] identifying the paper's Eq. 29 predictor on the rig's data (the paper's split)")
    code = main(["identify", "--train", str(rig / "all.csv"), "--out", str(out / "identify")])
    if code:
        return code
    print("[5] predictor vs co-simulation (derived from the physics and identified)")
    code = main(["compare", "--identification", str(out / "identify" / "identification.json"),
                 "--out", str(out / "compare")])
    if code:
        return code
    print(f"[6] closing the loop on rig data with an undeclared effect ({args.effect}); the calibrated model "
          "exported (Predictor.fmu, calibrated SSP)")
    eff_dir = out / f"rig_{args.effect}"
    code = main(["rig", "--out", str(eff_dir), "--engine", "inprocess", "--step", "0.001", "--workers",
                 str(args.jobs), "--inject", args.effect, "--no-plots"] + (["--quiet"] if args.quiet else []))
    if code:
        return code
    motor = (["--motor", args.motor] if getattr(args, "motor", None) else []) + \
        (["--params", str(args.params)] if getattr(args, "params", None) else [])
    code = main(["close-loop", "--train", str(eff_dir / "train.csv"), "--test", str(eff_dir / "test.csv"),
                 "--out", str(out / "close_loop"), "--export", str(out / "close_loop_export")] + motor
                + (["--quiet"] if args.quiet else []))
    if code:
        return code
    print("[7] exporting FMUs, L1B2Motor.ssp and L1B2Motor.fmu")
    code = main(["export", "--out", str(out / "export"), "--identification",
                 str(out / "identify" / "identification.json")])
    if code:
        return code
    print("[8] a design study: speed over the motor's tolerances at 220 V, 0.05 kg (50 draws, on Dask)")
    from .physics.params import SYSTEM_MODELS_DIR
    code = main(["sweep", "--spec", str(SYSTEM_MODELS_DIR / "studies" / "tolerances_220V.toml"),
                 "--out", str(out / "sweep"), "--workers", str(args.jobs)] + (["--quiet"] if args.quiet else []))
    if code:
        return code
    print(f"demo outputs in {out}")
    return 0


def cmd_identify(args) -> int:
    """Maximum-likelihood identification of the Eq. 29 predictor (paper Eq. 32, 35)."""
    from .workflows import run_identification
    with StageBar(f"identify: fitting Eq. 29 ({args.starts} starts)", quiet=args.quiet):
        rep = run_identification(args.train, args.out, args.test, order=args.order, criterion=args.criterion,
                             fix=args.fix, n_starts=args.starts, seed=args.seed, test_abs_loads=args.test_loads,
                                 slider_mass_kg=args.slider_mass, plots_on=not args.no_plots,
                                 verbose=args.verbose, allow_unusual_units=args.allow_unusual_units,
                                 noise_fit=args.noise_fit, noise=args.noise, model=args.model)
    print(f"identify: {rep['data']['train_runs']} train runs, {rep['data']['test_runs']} test runs "
          f"({rep['data']['split']}); fit {rep['fit_time_s']:.1f} s")
    print("time and evaluations per stage of the fit:")
    print("\n".join(stage_lines(rep["convergence"].get("stages") or [])))
    for part in ("train", "test"):
        m = rep["metrics"][part]
        if m is None:
            continue
        for kind in ("one_step", "free_run"):
            x = m[kind]
            print(f"  {part:5s} {kind:8s} nrmse {pct(x['nrmse'])}  mean |rel| {pct(x['mean_abs_rel_error'])}  "
                  f"p95 |rel| {pct(x['p95_abs_rel_error'])}  (n={x['n_samples']})")
    from .data.coverage import data_check_lines
    print_input_checks(rep["checks"], rep["metrics"], data_check_lines(rep["checks"]))
    if rep.get("unidentifiable"):
        print(f"  warning: {len(rep['unidentifiable'])} parameter combination(s) the data cannot separate; "
              f"see {Path(args.out) / 'fit_report.txt'}")
    print(f"wrote {Path(args.out) / 'identification.json'}")
    return 0


def _read_identification(path: Path) -> dict:
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise L1B2Error(f"{path}: not an identification.json of `l1b2 identify` ({exc})") from None
    if not isinstance(doc, dict) or "predictor" not in doc:
        raise L1B2Error(f"{path}: not an identification.json of `l1b2 identify` (no 'predictor' section)")
    return doc


def _add_frequency_map_parser(sub) -> None:
    """The ``frequency-map`` subcommand's arguments."""
    p = sub.add_parser("frequency-map", help="design study: steady speed over drive frequency and V0, identified "
                                             "predictor vs the coupled physics (PNG, CSV, agreement)")
    p.add_argument("--identification", type=Path, required=True, help="identification.json from `l1b2 identify`")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--frequencies", type=float, nargs="+", metavar="HZ",
                   help="drive frequencies [Hz] (default: 41 over TRAIN's range, else +-500 Hz around the nominal)")
    p.add_argument("--voltages", type=float, nargs="+", default=[220.0, 324.0], metavar="V", help="V0 values [V]")
    p.add_argument("--load", type=float, default=0.0, help="load [kg] (default 0)")
    p.add_argument("--position", type=float, default=0.0, help="slider position [m] (default 0)")
    _motor_args(p)
    p.set_defaults(func=cmd_frequency_map)


def cmd_frequency_map(args) -> int:
    """Steady speed over drive frequency and V0: the identified predictor against the coupled physics."""
    from .workflows import run_frequency_map
    rep = run_frequency_map(_read_identification(args.identification), args.out, _motor(args),
                            frequencies_Hz=args.frequencies, voltages_V=tuple(args.voltages), s_m=args.position,
                            load_kg=args.load)
    a = rep["agreement"]
    print(f"  predictor vs physics over {a['points']} points: rms {a['rms_rel']:.2%} (shape only "
          f"{a['shape_rms_rel']:.2%}), max |difference| {a['max_abs_m_s'] * 1e3:.1f} mm/s")
    if rep["frequency_response"] is None:
        print("  warning: the identification has no frequency response (TRAIN at one drive frequency): the "
              "predictor's speed does not change with frequency")
    print(f"  figure: {rep['figure']}")
    return 0


def cmd_compare(args) -> int:
    """Predictor (derived and identified) against the co-simulation's steady states."""
    from .workflows import run_comparison
    ident = _read_identification(args.identification) if args.identification else None
    rep = run_comparison(args.out, _motor(args), ident, order=args.order)
    for key, c in rep["cases"].items():
        print(f"  {key:38s} max |rel err| {c['max_abs_rel_error']:.2%}  rms {c['rms_rel_error']:.2%}  "
              f"({c['n_points']} points)")
        if c.get("extrapolation"):
            shares = ", ".join(f"{col} {share:.0%}" for col, share in c["extrapolation"].items())
            print(f"  warning: {key}: grid points outside the identification's training range ({shares}): "
                  "errors there are extrapolation")
    print(f"wrote {Path(args.out) / 'comparison.json'}")
    return 0


def _fold_settings(args) -> dict:
    """``--clock-folds``, ``--fold-unit``, ``--refit-repeats`` and ``--tie-repeats`` as the loop's settings; L1B2Error
    (one line) for a bad value."""
    if args.clock_folds not in CLOCK_FOLDS:
        raise L1B2Error(f"--clock-folds must be one of {', '.join(CLOCK_FOLDS)}, got {args.clock_folds!r}")
    if args.fold_unit not in FOLD_UNITS:
        raise L1B2Error(f"--fold-unit must be one of {', '.join(FOLD_UNITS)}, got {args.fold_unit!r}")
    out = {"clock_folds": args.clock_folds, "fold_unit": args.fold_unit}
    for name in ("refit_repeats", "tie_repeats"):
        given = getattr(args, name)
        out[name] = int(given) if str(given).isdigit() else 0
        if out[name] < 1:
            raise L1B2Error(f"--{name.replace('_', '-')} must be a whole number >= 1, got {given!r}")
    return out


def _run_close_loop(args, say):
    from .workflows import run_close_loop
    from .closeloop.settings import response_setting
    return run_close_loop(args.train, args.test, args.out, order=args.order, k_folds=args.folds,
                          alpha=args.alpha, min_gain=args.min_gain, seed=args.seed,
                          max_rounds=args.max_rounds, min_cv_gain=args.min_cv_gain,
                          min_cv_drop=args.min_cv_drop, screen_alpha=args.screen_alpha or None,
                          noise_fit=args.noise_fit, noise=args.noise, baseline=args.baseline, **_fold_settings(args),
                          **response_setting(args.response_columns, args.no_response_columns),
                          slider_mass_kg=args.slider_mass, plots_on=not args.no_plots, progress=say,
                          allow_unusual_units=args.allow_unusual_units, export_dir=args.export,
                          motor=_motor(args) if args.export is not None else None,
                          workers=args.workers, scheduler=args.scheduler, test_abs_loads=args.test_loads)


def cmd_close_loop(args) -> int:
    """Residual -> missing effect -> extended model; error before and after on TEST."""
    with StageBar("close-loop", quiet=args.quiet, prefix="[close-loop] ") as bar:
        result = _run_close_loop(args, bar.stage)
    d = result.diagnosis
    print(f"data: {result.checks['split']}")
    print(f"diagnosis: {d['message']}" + (f"; traced to {', '.join(d['traced_to'])}" if d["traced_to"] else ""))
    print(result.rounds_table())
    print(result.before_after_table())
    print("time and evaluations per stage (fits: identifications, fold refits included):")
    print("\n".join(stage_lines(result.stages)))
    from .closeloop.report import loop_check_lines
    from .data.coverage import data_check_lines
    print_input_checks(result.checks, {"baseline " + k: v for k, v in result.baseline.items()},
                       data_check_lines(result.checks) + loop_check_lines(d, result.baseline_parameters))
    print(f"wrote {Path(args.out) / 'report.json'} and report.md ({result.wall_time_s} s)")
    if args.export is not None:
        _print_calibrated(args.export, result.calibrated_note)
    return 0


def _print_calibrated(out: Path, note: str = "") -> None:
    """Where each effect went, the held-out check of the calibrated SSP, the files written."""
    import json
    man = json.loads((Path(out) / "calibrated_manifest.json").read_text())
    for e in man["effects"]:
        sub = e["subsystems"]
        se = sub.get("stderr") or {}
        values = ", ".join(f"{k} = {v:.4g}" + ("" if se.get(k) is None else f" +- {se[k]:.2g} (se)")
                           for k, v in sub["parameters"].items())
        where = (f"; {values} in the calibrated SSP"
                 if sub["mapped"] else f"; subsystems: not mapped ({sub['reason']})")
        print(f"  {e['label']}: Predictor.fmu{where}")
    chk = man.get("held_out_check")
    if chk:
        f = {k: ("-" if chk[k] is None else f"{100 * chk[k]:.2f} %")
             for k in ("extended_predictor_nrmse", "calibrated_ssp_nrmse", "uncalibrated_ssp_nrmse")}
        print(f"  TEST free-run nrmse: extended predictor {f['extended_predictor_nrmse']}, calibrated SSP "
              f"{f['calibrated_ssp_nrmse']}, uncalibrated SSP {f['uncalibrated_ssp_nrmse']}")
    print(f"wrote {Path(out) / 'fmus' / 'Predictor.fmu'}" + (f" ({note})" if note else "")
          + (f", {Path(out) / man['calibrated_ssp']['path']}" if man["calibrated_ssp"]["included"] else "")
          + f" and {Path(out) / 'calibrated_manifest.json'}")


def cmd_export(args) -> int:
    """The drop-in deliverables: subsystem FMUs, Predictor.fmu, L1B2Motor.ssp and L1B2Motor.fmu."""
    from .fmi.export import export_all
    predictor = None
    from .workflows import export_from_report, output_dir
    if args.from_report is not None:
        if args.identification or args.no_predictor:
            raise L1B2Error("--from-report exports the calibrated Predictor.fmu only: drop --identification "
                            "and --no-predictor")
        export_from_report(args.from_report, args.out, mp=_motor(args))
        _print_calibrated(args.out)
        return 0
    if args.identification:
        predictor = _read_identification(args.identification)["predictor"]
    with output_dir(args.out, command="export") as tmp:
        if not args.identification and not args.no_predictor:
            from .predictor.derive import derive_predictor_setup
            predictor = derive_predictor_setup(_motor(args)).to_dict()
        manifest = export_all(tmp, mp=_motor(args), predictor=predictor)
    for f in manifest.get("files", []):
        print(f"  {f.get('path')}")
    for name, info in manifest.get("native", {}).items():
        if not info.get("included"):
            print(f"  (no native {name} FMU: {info.get('reason')})")
    if not args.identification and not args.no_predictor:
        print("  (Predictor.fmu carries the physical model's linearization; give --identification to ship "
              "identified parameters)")
    print(f"wrote {Path(args.out) / 'manifest.json'}")
    return 0


def cmd_injections(args) -> int:
    from .rig.experiment import DATA_INJECTIONS, INJECTIONS, RUN_INJECTIONS
    for e in list(INJECTIONS.values()) + list(DATA_INJECTIONS.values()) + list(RUN_INJECTIONS.values()):
        params = ", ".join(f"{k}={v:g}" for k, v in e.params.items())
        print(f"{e.name}  [{e.regressor}]\n    {e.description}\n    {params}")
    return 0


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except L1B2Error as exc:
        print(f"l1b2: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("l1b2: interrupted", file=sys.stderr)
        return 130
    except FileNotFoundError as exc:
        print(f"l1b2: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # full disk, no permission, ...: the output folder is left as it was
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"l1b2: error: {exc.strerror or exc}{where}; earlier results are untouched",
              file=sys.stderr)
        return 2
    except RecursionError:
        print("l1b2: error: an input is nested too deeply to read (a JSON or TOML file with deeply nested "
              "objects or tables?)", file=sys.stderr)
        return 2
    except MemoryError:
        print("l1b2: error: out of memory (a smaller input or study, or a larger machine); "
              "earlier results are untouched", file=sys.stderr)
        return 2
    except Exception as exc:  # a bug: one line (the traceback with L1B2_TRACEBACK=1)
        if os.environ.get("L1B2_TRACEBACK"):
            raise
        text = " ".join(str(exc).split()) or "no message"
        print(f"l1b2: error: internal error ({type(exc).__name__}: {text}); please report it "
              "(L1B2_TRACEBACK=1 shows the traceback)", file=sys.stderr)
        return 3


if __name__ == "__main__":
    sys.exit(main())
