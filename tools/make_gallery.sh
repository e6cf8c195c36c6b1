#!/bin/bash
# The gallery figures of docs/gallery.md on a small data set (~3 min on 2 cores):
#   bash tools/make_gallery.sh OUTDIR [PYTHONPATH]   (PYTHONPATH: another checkout's fmu_src, for before/after)
# then copy the PNGs listed in docs/gallery.md into docs/gallery/.
set -e
OUT=$1; shift
export OPENBLAS_NUM_THREADS=1 MPLBACKEND=Agg
[ -n "$1" ] && export PYTHONPATH=$1
L="${PYTHON:-python} -m l1b2.cli"
rm -rf $OUT; mkdir -p $OUT; cd $OUT
${PYTHON:-python} -c "import l1b2, os; print(os.path.dirname(l1b2.__file__))"
$L rig --out rig --engine inprocess --voltages 220,324 --loads=-0.09,-0.05,0,0.05,0.09 --step 1e-3 --workers 1 --quiet --inject pulley_friction > rig.log
${PYTHON:-python} -c "import pandas as pd; pd.read_csv('rig/all.csv').drop(columns='speed_m_s').to_csv('nospeed.csv', index=False)"
cp rig/all.json nospeed.json
$L identify --train nospeed.csv --out ident > ident.log
$L close-loop --train rig/all.csv --out cl --export cl_export --workers 1 --max-rounds 1 --quiet > cl.log
$L simulate --engine inprocess --out sim.csv --plot simulate.png --step 1e-3 > sim.log
$L compare --out compare > compare.log
cat > study.toml <<'T'
[study]
name = "tolerances at 220 V (small)"
seed = 1
engine = "inprocess"
design = "montecarlo"
draws = 12
chunk_size = 6
[simulation]
step_s = { value = 1e-3, unit = "s" }
max_time_s = { value = 2.0, unit = "s" }
[operating_points]
V0 = { values = [220.0, 324.0], unit = "V" }
load = { values = [0.05], unit = "kg" }
direction = { values = [1], unit = "1" }
[parameters]
"Stator.P0_N" = { distribution = "normal", sd = 0.3, bounds = [5.45, 7.25], unit = "N" }
"Interface.mu_p" = { distribution = "uniform", low = 0.13, high = 0.17, unit = "1" }
[outputs]
mean_speed = { middle = 0.5 }
traverse_time = true
stall = true
T
$L sweep --spec study.toml --out sweep --workers 0 --quiet > sweep.log
echo done
