#!/usr/bin/env python
"""Run every benchmark in bench/ (each prints its own side-by-side table).

bench_closeloop.py, bench_cosim.py, bench_identify.py, bench_sweep.py: every
``bench_*.py`` beside this file is run, in name order.
"""
import runpy
import sys
from pathlib import Path

here = Path(__file__).resolve().parent
for script in sorted(here.glob("bench_*.py")):
    print(f"\n=== {script.name} ===", flush=True)
    sys.argv = [str(script)]
    runpy.run_path(str(script), run_name="__main__")
