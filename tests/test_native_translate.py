"""The Python -> C translator of the plain-float kernels (l1b2.fmi.native.translate): one physics.

The generated C of the fused coupled step (l1b2.physics.coupled.motor_substeps and
every kernel it calls) is compiled here and run beside the *plain Python* function
(not the numba-compiled one) on the same state vectors: the results must be equal
bit for bit, over runs with loads, both directions, end stops, self-heating, bar
waviness and bump, pulley friction and the pure-slip interface.
"""

from __future__ import annotations

import ctypes
import math
import random
import shutil
import subprocess

import numpy as np
import pytest
from l1b2.fmi.native.translate import Translator, TranslationError, translate_kernels

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")
CFLAGS = ["-O2", "-std=c99", "-fPIC", "-shared", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror",
          "-Wno-unused-parameter", "-Wno-unused-function"]


def _compile(src: str, tmp_path, name: str) -> ctypes.CDLL:
    c = tmp_path / f"{name}.c"
    c.write_text(src)
    lib = tmp_path / f"{name}.so"
    cc = shutil.which("cc") or shutil.which("gcc")
    subprocess.run([cc, *CFLAGS, "-o", str(lib), str(c), "-lm"], check=True, capture_output=True, text=True)
    return ctypes.CDLL(str(lib))


@pytest.fixture(scope="module")
def motor_lib(tmp_path_factory):
    lib = _compile(translate_kernels(), tmp_path_factory.mktemp("kern"), "motor_kernels")
    f = lib.l1b2k_motor_substeps
    dbl = ctypes.POINTER(ctypes.c_double)
    f.argtypes = [dbl, dbl, dbl, ctypes.c_long, ctypes.c_long, ctypes.c_double]
    f.restype = ctypes.c_long
    return f


def _ptr(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def _scenarios():
    from l1b2.physics.params import load_motor
    mp = load_motor()
    return {
        "reference": (mp, dict(V_s=67.1, direction=1.0, m_load=0.0), -0.015, 0.0, False),
        "load, CH2": (mp, dict(V_s=60.0, direction=-1.0, m_load=0.25), 0.010, 0.0, False),
        "end stop": (mp, dict(V_s=67.1, direction=1.0, m_load=-0.1), 0.0195, 0.05, False),
        "heating, waviness, bump, pulley": (
            mp.replace(stator__thermal_tau_s=0.05, stator__heating_K_per_V2=1e-4, stator__df_dT_l_Hz_per_K=-10.0,
                       stator__bar_wave_amp_m=2e-6, stator__bar_bump_amp_m=3e-6, stator__bar_bump_center_m=0.002,
                       slider__pulley_mu=0.05),
            dict(V_s=67.1, direction=1.0, m_load=0.1), -0.004, 0.0, False),
        "pure slip, sticking": (mp, dict(V_s=20.0, direction=1.0, m_load=0.5), 0.0, 0.0, True),
    }


class _Cell:
    """A table cell whose entries are Python floats (numpy scalars would bring numpy's complex arithmetic in)."""

    def __init__(self, a):
        self.a, self.shape = a, a.shape

    def __getitem__(self, ij):
        return float(self.a[ij])


def _run_both(kernel, mp, inputs, s0, v0, pure_slip, n_calls=60, n=25, h=2e-4):
    """The plain Python motor_substeps (Python floats in lists) and the C one from the same initial state,
    call after call."""
    from l1b2.cosim.engine import FusedSteps, InProcessMotor
    from l1b2.physics import coupled as cp
    motor = InProcessMotor(mp, h_s=h, pure_slip=pure_slip, fused=False)
    motor.initialize(**inputs, s0=s0, v0=v0)
    fs = FusedSteps(motor, cp.motor_substeps)
    fs.load()
    assert fs.set_inputs(0.0, h)
    table = fs._table()
    x_py, x_c = fs.x.tolist(), fs.x.copy()
    p = np.ascontiguousarray(fs.p)
    p_py = p.tolist()
    cell, cell_k = np.zeros((11, 2)), -1
    done = 0
    trace = []
    for _ in range(n_calls):
        k_py = cp.motor_substeps(x_py, p_py, _Cell(cell), cell_k, n, h)
        k_c = kernel(_ptr(x_c), _ptr(p), _ptr(np.ascontiguousarray(cell)), cell_k, n, h)
        assert k_py == k_c
        assert all(type(v) in (float, int) for v in x_py)  # no numpy scalars
        assert np.array_equal(np.array(x_py), x_c, equal_nan=True), np.flatnonzero(np.array(x_py) != x_c)
        done += k_py
        trace.append(list(x_py))
        if x_py[cp.REASON] == cp.REASON_CELL:
            cell_k = int(x_py[cp.NEED_CELL])
            cell = table.cell_array(cell_k)
            assert cell is not None
        elif x_py[cp.REASON] == cp.REASON_BLOCKS:
            break
    return np.array(trace), done


@pytest.mark.parametrize("name", list(_scenarios()))
def test_generated_c_step_is_bit_identical_to_the_python_kernel(motor_lib, name):
    # reference: l1b2.physics.coupled.motor_substeps run as plain Python on the same vectors
    from l1b2.physics import coupled as cp
    mp, inputs, s0, v0, pure_slip = _scenarios()[name]
    trace, done = _run_both(motor_lib, mp, inputs, s0, v0, pure_slip)
    assert done > 1000
    v = trace[:, cp.V]
    if name == "end stop":
        assert np.any(trace[:, cp.STOP] == 1.0) and trace[-1, cp.S] == mp.slider.s_max_m
    elif name == "pure slip, sticking":
        assert np.any(trace[:, cp.STUCK] == 1.0) and np.any(trace[:, cp.STUCK] == 0.0)
    else:
        assert np.max(np.abs(v)) > 0.01
    if name.startswith("heating"):
        assert trace[-1, cp.T_ST] > 26.0  # self-heating moved the stator temperature


def _translate(*functions, param_types=None):
    return Translator({f.__name__: f for f in functions}, param_types or {}, 10).translate("test")


def py_mod(a, b):
    return a % b


def py_min_max(a, b):
    return min(a, b), max(a, b)


def c_div(a_re, a_im, b_re, b_im):
    z = complex(a_re, a_im) / complex(b_re, b_im)
    w = z * complex(b_im, a_re) - 2.5 * z
    return z.real, z.imag, abs(w), w.real, w.imag


def test_translator_keeps_pythons_semantics(tmp_path):
    # reference: CPython evaluating the same functions (floored modulo, min/max ties and NaN,
    # complex division _Py_c_quot, float-times-complex, abs of a complex): bit-identical
    lib = _compile(_translate(py_mod, py_min_max, c_div), tmp_path, "sem")
    d = ctypes.c_double
    lib.l1b2k_py_mod.argtypes = [d, d]
    lib.l1b2k_py_mod.restype = d

    class T2(ctypes.Structure):
        _fields_ = [("v", d * 2)]

    class T5(ctypes.Structure):
        _fields_ = [("v", d * 5)]
    lib.l1b2k_py_min_max.argtypes = [d, d]
    lib.l1b2k_py_min_max.restype = T2
    lib.l1b2k_c_div.argtypes = [d] * 4
    lib.l1b2k_c_div.restype = T5
    rng = random.Random(3)
    values = [0.0, -0.0, 1.0, -1.0, 2.5, -7.25, math.pi, -math.e, 1e-300, 6.5, -13.0]
    values += [rng.uniform(-50, 50) for _ in range(40)]
    for a in values:
        for b in values:
            if b != 0.0:
                want = py_mod(a, b)
                got = lib.l1b2k_py_mod(a, b)
                assert got == want and math.copysign(1, got) == math.copysign(1, want), (a, b)
            assert tuple(lib.l1b2k_py_min_max(a, b).v) == py_min_max(a, b)
    nan = float("nan")
    assert lib.l1b2k_py_min_max(1.0, nan).v[0] == 1.0 and math.isnan(lib.l1b2k_py_min_max(nan, 1.0).v[0])
    for _ in range(500):
        a = [rng.uniform(-1e3, 1e3) for _ in range(4)]
        if a[2] == 0.0 and a[3] == 0.0:
            continue
        assert tuple(lib.l1b2k_c_div(*a).v) == c_div(*a)


def uses_a_list(x):
    y = [x, x]
    return y[0]


def uses_while(x):
    while x > 1.0:
        x = x / 2.0
    return x


@pytest.mark.parametrize("fn, what", [(uses_a_list, "List"), (uses_while, "While")])
def test_translator_refuses_python_outside_its_subset(fn, what):
    # reference: the subset listed in l1b2.fmi.native.translate's docstring
    with pytest.raises(TranslationError, match=rf"{fn.__name__} \(line \d+ .*\): .*{what}"):
        _translate(fn)


def _effect_specs():
    """One spec per kernel kind, and the generic terms over every regressor and pair (scalars as the library's)."""
    from l1b2.predictor.effects.generic import PAIR_REGRESSORS, REGRESSORS
    ranges = {"t_lo": 5.0, "t_hi": 65.0, "s_lo": -0.018, "s_hi": 0.019, "n_inner": 24, "load_abs": 0.3,
              "V_lo": 200.0, "V_hi": 330.0, "v_lo": 0.01, "v_hi": 0.35, "m_s": 0.12, "T_lo": 24.0, "T_hi": 41.0}
    specs = [{"kind": "thermal_drift", "t_lo": 5.0, "t_hi": 65.0, "n_inner": n} for n in (2, 4)]
    specs += [{"kind": "thermal_drift_T", "T_ref": 31.0}, {"kind": "direction_asymmetry"},
              {"kind": "bar_waviness", "period_m": 4.2e-3}, {"kind": "local_defect", "center_m": 2e-3, "width_m": 1.2e-3},
              {"kind": "load_path_friction"}, {"kind": "drive_saturation"}, {"kind": "speed_dependent_friction"},
              {"kind": "inertia_mismatch", "m_s": 0.12}, {"kind": "load_slope_voltage", "V_ref": 280.0},
              {"kind": "damping_voltage", "V_ref": 280.0}, {"kind": "position_load", "s_lo": -0.018, "s_hi": 0.019}]
    specs += [{"kind": "smooth", "regressor": r, **ranges} for r in REGRESSORS]
    specs += [{"kind": "smooth_pair", "a": a, "b": b, **ranges}
              for i, a in enumerate(PAIR_REGRESSORS) for b in PAIR_REGRESSORS[i + 1:]]
    # a channel and a run-level signal of each input (the FMU's current value), every form and transform
    specs += [{"kind": "channel", "channel": "temperature_C", "form": f, "level": lv, "mean": 31.0, "sd": 4.0,
               "run_spread": 0.0} for f in ("friction", "force_factor", "force") for lv in ("run", "sample")]
    # the quadratic and odd shapes, clipped to TRAIN's range 24-41 degC (samples fall on both sides of it)
    specs += [{"kind": "channel", "channel": "temperature_C", "form": f, "level": "sample", "mean": 31.0, "sd": 4.0,
               "run_spread": 0.0, "shape": sh, "lo": 24.0, "hi": 41.0}
              for f in ("friction", "force_factor", "force") for sh in ("quadratic", "odd")]
    # and growing with the load's size (|m| / 0.3 kg), in every shape
    specs += [{"kind": "channel", "channel": "temperature_C", "form": f, "level": "sample", "mean": 31.0, "sd": 4.0,
               "run_spread": 0.0, "shape": sh, "lo": 24.0, "hi": 41.0, "by": "load", "load_abs": 0.3}
              for f in ("friction", "force_factor", "force") for sh in ("linear", "quadratic", "odd")]
    # the inertia form (the channel scaling the moving mass, -m_s d a_base) in every shape and level
    specs += [{"kind": "channel", "channel": "temperature_C", "form": "inertia", "level": lv, "mean": 31.0,
               "sd": 4.0, "run_spread": 0.0, "shape": sh, "lo": 24.0, "hi": 41.0, "m_s": 0.12}
              for sh in ("linear", "quadratic", "odd") for lv in ("run", "sample")]
    # the damping form (the channel scaling the viscous damping, -d v_base / 0.2 m/s) in its shapes and levels
    specs += [{"kind": "channel", "channel": "temperature_C", "form": "damping", "level": lv, "mean": 31.0,
               "sd": 4.0, "run_spread": 0.0, "shape": sh, "lo": 24.0, "hi": 41.0}
              for sh in ("linear", "quadratic") for lv in ("run", "sample")]
    specs += [{"kind": "run_level", "channel": c, "transform": tr, "mean": m, "sd": sd, "run_spread": 0.0}
              for c, tr, m, sd in (("voltage_V", "none", 280.0, 40.0), ("load_kg", "drive", 0.01, 0.2),
                                   ("load_kg", "abs", 0.15, 0.1), ("direction", "none", 0.0, 1.0),
                                   ("temperature_C", "none", 30.0, 3.0))]
    # a logged temperature's run mean centred on its runs' mean, times the direction (the loop's d*<column>)
    specs += [{"kind": "run_level", "channel": "temperature_C", "transform": "drive", "centre": 31.0, "mean": 0.2,
               "sd": 3.0, "run_spread": 0.0}]
    # and that run mean centred, squared, less -1.3 times itself (the loop's <column>^2, a channel's curvature)
    specs += [{"kind": "run_level", "channel": "temperature_C", "transform": "square", "centre": 31.0, "slope": -1.3,
               "mean": 9.0, "sd": 6.0, "run_spread": 0.0}]
    # the reduced run-level forms, each without one of its three columns (two parameters)
    specs += [{"kind": "run_level", "channel": "load_kg", "transform": "drive", "mean": 0.01, "sd": 0.2,
               "run_spread": 0.0, "drop": d} for d in ("gain", "offset", "load")]
    return specs


def test_effect_kernels_in_c_equal_the_python_kernels_bit_for_bit(tmp_path):
    # reference: l1b2.predictor.effects.kernels run as plain Python (Python floats): the generated C
    # (l1b2k_effect_force) gives the same force bit for bit, for every kind, regressor and pair, over samples inside,
    # at the ends of and beyond the ranges (the B-spline knots included)
    from l1b2.fmi.native.translate import translate_effect_kernels
    from l1b2.predictor import effects as fx
    from l1b2.predictor.effects import kernels as ek
    lib = _compile(translate_effect_kernels(), tmp_path, "effect_kernels")
    f = lib.l1b2k_effect_force
    dbl = ctypes.POINTER(ctypes.c_double)
    f.argtypes = [ctypes.c_long, dbl, dbl, dbl]
    f.restype = ctypes.c_double
    rng = random.Random(4)
    specs = _effect_specs()
    assert {s["kind"] for s in specs} == set(ek.KERNEL_KINDS)
    samples = []
    for k in range(300):
        x = [rng.uniform(0.0, 70.0), rng.uniform(-0.025, 0.025), rng.uniform(0.0, 400.0), rng.uniform(-0.4, 0.4),
             rng.choice([-1.0, 1.0]), rng.uniform(20.0, 45.0), rng.uniform(-0.4, 0.4), rng.uniform(-5.0, 5.0)]
        if k < 20:   # on the knots of the time spline and the ranges' ends
            x[0] = 5.0 + 60.0 * (k % 7) / 7
            x[1] = (-0.018, 0.019, 0.0)[k % 3]
        samples.append(x)
    n_cmp = 0
    for spec in specs:
        kind, q = ek.spec_scalars(spec)
        width = fx.family(spec["kind"]).width(spec)
        phi = [rng.gauss(0.0, 1.0) for _ in range(width)]
        qa, pa = (ctypes.c_double * len(q))(*q), (ctypes.c_double * len(phi))(*phi)
        for x in samples:
            want = ek.effect_force(kind, x, q, phi)
            got = f(kind, (ctypes.c_double * 8)(*x), qa, pa)
            assert got == want or (math.isnan(got) and math.isnan(want)), (spec, x)
            n_cmp += 1
    assert n_cmp == len(specs) * len(samples)
