"""Terminal output of the command line: a stage progress bar and the input checks' warnings."""

from __future__ import annotations

import sys
import threading

__all__ = ["StageBar", "print_input_checks", "pct", "stage_lines"]


def pct(x) -> str:
    """A share as a percentage with two decimals; '-' for None or NaN."""
    return "-" if x is None or x != x else f"{x:.2%}"


def stage_lines(stages: list) -> list[str]:
    """One line per stage record, then their total: wall [s], CPU [s] of this process, identifications and evaluations.

    Takes the close loop's records (:class:`l1b2.closeloop.stages.StageClock`: ``wall_s``, ``cpu_s``,
    ``identifications``, ``nfev``) and an identification's (``convergence["stages"]``: ``time_s``, ``cpu_s`` and
    ``nfev`` where the stage evaluates). A count a record does not hold is printed as '-' and left out of the total.
    """
    def cell(r, key):
        return "-" if r.get(key) is None else str(int(r[key]))

    lines = [f"  {'stage':60s} {'wall [s]':>8s} {'CPU [s]':>8s} {'fits':>5s} {'evaluations':>11s}"]
    total = {"wall_s": 0.0, "cpu_s": 0.0, "identifications": None, "nfev": None}
    for r in stages:
        wall = float(r.get("wall_s", r.get("time_s", 0.0)))
        lines.append(f"  {str(r['stage'])[:60]:60s} {wall:8.1f} {float(r['cpu_s']):8.1f} "
                     f"{cell(r, 'identifications'):>5s} {cell(r, 'nfev'):>11s}")
        total["wall_s"] += wall
        total["cpu_s"] += float(r["cpu_s"])
        for key in ("identifications", "nfev"):
            if r.get(key) is not None:
                total[key] = (total[key] or 0) + int(r[key])
    lines.append(f"  {'total':60s} {total['wall_s']:8.1f} {total['cpu_s']:8.1f} "
                 f"{cell(total, 'identifications'):>5s} {cell(total, 'nfev'):>11s}")
    return lines


def print_input_checks(checks: dict, metrics: dict, test_lines=()) -> None:
    """Warnings of a report's input checks and diverged runs (shared by identify and close-loop); ``test_lines``:
    more checks, one warning each (empty lines skipped; the gaps filled on reading, :func:`l1b2.data.gaps.gap_lines`,
    and the close loop's own, :func:`l1b2.closeloop.report.loop_check_lines`)."""
    found = [m for part in ("train", "test") for m in checks.get("unusual_units", {}).get(part, [])]
    if checks.get("allow_unusual_units") and found:
        print(f"  warning: --allow-unusual-units accepted {len(found)} likely unit mistake(s), e.g.: {found[0]}")
    if checks.get("extrapolation"):
        runs = [str(f["run"]) for f in checks.get("test_runs_outside_training_range", [])]
        print(f"  warning: TEST {checks['extrapolation']} (runs {', '.join(runs[:10])}"
              f"{', ...' if len(runs) > 10 else ''})")
    for line in test_lines:
        if line:
            print(f"  warning: {line}")
    for part, m in metrics.items():
        for kind, x in (m or {}).items():
            if x.get("n_diverged_runs"):
                print(f"  warning: {part} {kind}: {x['n_diverged_runs']} of {x['n_runs']} runs diverged "
                      f"(non-finite or absurd prediction; excluded from the metrics): runs "
                      f"{', '.join(map(str, x['diverged_runs'][:10]))}{', ...' if x['n_diverged_runs'] > 10 else ''}")


class StageBar:
    """A progress bar for work of unknown length: the current stage and the elapsed time, redrawn every second.

    Shown only on a terminal (``sys.stderr.isatty()``) and without ``--quiet``, so logs and captured output
    keep their lines; stage lines given to :meth:`stage` are printed above it either way (unless quiet).
    """

    def __init__(self, desc: str, *, quiet: bool = False, prefix: str = ""):
        from tqdm import tqdm
        self.quiet, self.prefix = quiet, prefix
        self.bar = tqdm(total=None, desc=desc, bar_format="{desc} [{elapsed}]", file=sys.stderr, leave=False,
                        disable=quiet or not sys.stderr.isatty())
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, daemon=True)

    def _tick(self):
        while not self._stop.wait(1.0):
            self.bar.refresh()

    def stage(self, text: str) -> None:
        if not self.quiet:
            self.bar.write(f"{self.prefix}{text}", file=sys.stdout)
            sys.stdout.flush()
        self.bar.set_description_str(text)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.bar.close()
        return False
