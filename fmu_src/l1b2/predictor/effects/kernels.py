"""Per-sample force kernels of the effect families, in plain floats (the source of the native Predictor FMU's C).

The families' :meth:`~l1b2.predictor.effects.base.Effect.features` are
vectorised numpy over whole data sets (what the identification needs). The
native ``Predictor.fmu`` evaluates one sample per communication step; its C is
generated (:func:`l1b2.fmi.native.translate.translate_effect_kernels`) from the
kernels of this module, written in the plain-float subset that translator
accepts. Each kernel returns one effect's force ``features(spec, x) @ phi``
[N, drive coordinates] at one sample:

* ``x``: the signals of one sample, indexed by :data:`SIGNAL_INDEX` (the order
  of :data:`l1b2.predictor.effects.base.SIGNALS`);
* ``q``: the spec's scalars in the order :data:`SPEC_KEYS` lists for the kind
  (:func:`spec_scalars` encodes a spec; a regressor is its index in
  :data:`REGRESSOR_INDEX`);
* ``phi``: the effect's parameters, one per feature column.

:data:`KERNEL_KINDS` lists the kinds with a kernel: every family of the package
(``channel`` and ``run_level`` for a signal of :data:`~l1b2.predictor.effects.base.SIGNALS`
that an input of ``Predictor.fmu`` gives, :func:`l1b2.predictor.effects.channels.fmu_signal`:
a run-level signal is the input's current value, exact when the input is constant within a run)
but ``run_level_category``, whose every hypothesis reads a logged channel; a
spec reading a logged channel through an input of its own
(:func:`l1b2.predictor.effects.channels.channel_inputs`) has no kernel either
(:func:`spec_scalars` says so): those models, and those of a family registered
outside the package, stay Python FMUs. A change of a family's features needs the same change in its kernel:
the tests compare every kernel with its family's vectorised features.
"""

from __future__ import annotations

import math

from ...units import G_M_S2
from .base import SIGNALS, SPEED_REF, V_REF, EffectSpecError
from .channels import (FORMS, G_N_PER_KG, INTERACTIONS, RUN_LEVEL_COLUMNS, SHAPES, TRANSFORMS, dropped_column,
                       export_problem, fmu_signal, signal_key)

#: index of each signal in ``x``
SIG_T, SIG_S, SIG_V0, SIG_LOAD, SIG_D, SIG_TEMP, SIG_VB, SIG_AB = range(len(SIGNALS))
SIGNAL_INDEX = dict(zip(SIGNALS, range(len(SIGNALS))))
#: the regressors of the generic terms, by index (``l1b2.predictor.effects.generic.REGRESSORS``'s order)
REGRESSOR_INDEX = {"time": 0, "position": 1, "direction": 2, "load": 3, "voltage": 4, "speed": 5,
                   "acceleration": 6, "temperature": 7}
#: the generic terms' range scalars, in ``q`` after the regressor index (index 1 on: the smooth term's;
#: index 2 on: the pair term's)
RANGE_KEYS = ("t_lo", "t_hi", "s_lo", "s_hi", "n_inner", "load_abs", "V_lo", "V_hi", "v_lo", "v_hi", "m_s",
              "T_lo", "T_hi")
#: per kind with a kernel: its index (the dispatch code of :func:`effect_force`) and the spec's scalars
SPEC_KEYS = {
    "thermal_drift": ("t_lo", "t_hi", "n_inner"),
    "thermal_drift_T": ("T_ref",),
    "direction_asymmetry": (),
    "bar_waviness": ("period_m",),
    "local_defect": ("center_m", "width_m"),
    "load_path_friction": (),
    "drive_saturation": (),
    "speed_dependent_friction": (),
    "inertia_mismatch": ("m_s",),
    "load_slope_voltage": ("V_ref",),
    "damping_voltage": ("V_ref",),
    "position_load": ("s_lo", "s_hi"),
    "smooth": ("regressor",) + RANGE_KEYS,
    "smooth_pair": ("a", "b") + RANGE_KEYS,
    "channel": ("channel", "form", "mean", "sd"),
    "run_level": ("channel", "transform", "mean", "sd"),
}
KERNEL_KINDS = tuple(SPEC_KEYS)
(K_THERMAL, K_THERMAL_T, K_DIRECTION, K_BAR, K_DEFECT, K_LOAD_PATH, K_SATURATION, K_DRAG, K_INERTIA,
 K_LOAD_V, K_DAMPING_V, K_POSITION_LOAD, K_SMOOTH, K_PAIR, K_CHANNEL, K_RUN_LEVEL) = range(len(KERNEL_KINDS))
#: the codes of a channel's form and of a run-level signal's transform in ``q``
#: (:data:`l1b2.predictor.effects.channels.FORMS` and ``TRANSFORMS``)
FORM_FRICTION, FORM_FORCE_FACTOR, FORM_FORCE, FORM_INERTIA, FORM_DAMPING = range(len(FORMS))
#: added to a channel's form code in ``q[1]`` for the quadratic and the odd shape (then ``q[4:6]``: TRAIN's
#: range of ``z``), and for an interaction with the load (then ``q[6]``: TRAIN's largest load size ``load_abs``);
#: the inertia form has ``q[4:7]`` in any shape and the slider's mass ``m_s`` in ``q[7]``; the damping form reads
#: ``v_base`` and no scalar of its own
QUADRATIC = len(FORMS)
ODD = 2 * len(FORMS)
BY_LOAD = len(SHAPES) * len(FORMS)
TR_NONE, TR_DRIVE, TR_ABS, TR_SQUARE = range(len(TRANSFORMS))
#: the codes in a run-level spec's ``q[4]`` of the column its reduced form leaves out (-1: none)
RL_GAIN, RL_OFFSET, RL_LOAD = range(len(RUN_LEVEL_COLUMNS))
#: the offsets of the range scalars in ``q`` (smooth: after the regressor; pair: after both)
R_T_LO, R_T_HI, R_S_LO, R_S_HI, R_N_INNER, R_LOAD_ABS, R_V_LO, R_V_HI, R_VB_LO, R_VB_HI, R_M_S, R_TEMP_LO, \
    R_TEMP_HI = range(len(RANGE_KEYS))
BSPLINE_U_MAX = 1.0 - 1e-12   #: bspline_basis clips its argument to [0, this]


def spec_scalars(spec) -> tuple[int, list[float]]:
    """``(kind index, q)`` of an effect spec: the scalars :data:`SPEC_KEYS` lists, regressors as indices.

    A range scalar a generic term does not read may be missing (0 in ``q``);
    :class:`EffectSpecError` for a kind without a kernel or a scalar the kernel reads that is missing.
    """
    kind = spec.get("kind")
    if kind not in SPEC_KEYS:
        raise EffectSpecError(f"effect kind {kind!r} has no per-sample kernel (l1b2.predictor.effects.kernels); "
                              f"kernels exist for {', '.join(KERNEL_KINDS)}")
    if kind in ("channel", "run_level"):
        return KERNEL_KINDS.index(kind), _signal_scalars(spec)
    q = []
    for key in SPEC_KEYS[kind]:
        if key in ("regressor", "a", "b"):
            if spec.get(key) not in REGRESSOR_INDEX:
                raise EffectSpecError(f"effect spec {kind!r}: {key} = {spec.get(key)!r} is not a regressor")
            q.append(float(REGRESSOR_INDEX[spec[key]]))
        elif key in spec:
            q.append(float(spec[key]))
        elif key in RANGE_KEYS:
            q.append(0.0)
        else:
            raise EffectSpecError(f"effect spec {kind!r} lacks the scalar {key!r}")
    return KERNEL_KINDS.index(kind), q


def _signal_scalars(spec) -> list[float]:
    """``q`` of a ``channel`` or ``run_level`` spec: the index of the input giving its signal, the form's or
    transform's code, mean and sd (:class:`EffectSpecError` when no input gives it or TRAIN's runs did not hold
    it constant: :func:`l1b2.predictor.effects.channels.export_problem`)."""
    why = export_problem(spec)
    if why:
        raise EffectSpecError(f"effect spec {spec.get('kind')!r} of {spec.get('channel')!r}: {why}")
    kind = spec["kind"]
    if kind == "run_level" and spec.get("transform") not in TRANSFORMS:
        raise EffectSpecError(f"effect spec 'run_level' of {spec.get('channel')!r}: transform "
                              f"{spec.get('transform')!r} has no per-sample kernel (one of {', '.join(TRANSFORMS)})")
    level = "run" if kind == "run_level" else str(spec.get("level"))
    sig = fmu_signal(signal_key(str(spec.get("channel")), level))
    if sig not in SIGNAL_INDEX:
        raise EffectSpecError(f"effect spec {kind!r} reads the logged channel {spec.get('channel')!r} through an "
                              "input of its own, which the native kernels do not have (they read "
                              f"{', '.join(SIGNALS)})")
    code = (TRANSFORMS.index(spec.get("transform", "none")) if kind == "run_level"
            else FORMS.index(spec.get("form")) if spec.get("form") in FORMS else -1)
    if code < 0:
        raise EffectSpecError(f"effect spec 'channel': form {spec.get('form')!r} is not one of {', '.join(FORMS)}")
    try:
        mean, sd = float(spec["mean"]), float(spec["sd"])
    except (KeyError, TypeError, ValueError):
        raise EffectSpecError(f"effect spec {kind!r} lacks a numeric 'mean' or 'sd'") from None
    if not sd > 0:
        raise EffectSpecError(f"effect spec {kind!r} of {spec.get('channel')!r}: standard deviation {sd} is not "
                              "positive")
    if kind == "channel" and spec.get("form") == "inertia":
        try:
            m_s = float(spec["m_s"])
        except (KeyError, TypeError, ValueError):
            raise EffectSpecError("effect spec 'channel' of form 'inertia' lacks a numeric 'm_s'") from None
        return [float(SIGNAL_INDEX[sig])] + _channel_shape_scalars(spec, code, mean, sd) + [m_s]
    if kind == "channel" and (spec.get("shape", "linear") != "linear" or spec.get("by")):
        return [float(SIGNAL_INDEX[sig])] + _channel_shape_scalars(spec, code, mean, sd)
    if kind == "run_level":
        return [float(SIGNAL_INDEX[sig]), float(code), mean, sd, float(dropped_column(spec)),
                float(spec.get("centre", 0.0)), float(spec.get("slope", 0.0))]
    return [float(SIGNAL_INDEX[sig]), float(code), mean, sd]


def _channel_shape_scalars(spec, code: int, mean: float, sd: float) -> list[float]:
    """``q[1:7]`` of a channel spec with a non-linear shape or an interaction: the code (form + shape's and
    interaction's offsets), mean, sd, TRAIN's range of ``z`` (0, 0 for the unclipped linear shape) and
    ``load_abs`` (0 without an interaction)."""
    shape, by = spec.get("shape", "linear"), spec.get("by") or ""
    if shape not in SHAPES:
        raise EffectSpecError(f"effect spec 'channel': shape {shape!r} is not one of {', '.join(SHAPES)}")
    if by and by not in INTERACTIONS:
        raise EffectSpecError(f"effect spec 'channel': interaction {by!r} is not one of {', '.join(INTERACTIONS)}")
    z_lo = z_hi = load_abs = 0.0
    if shape != "linear":
        try:
            z_lo, z_hi = (float(spec["lo"]) - mean) / sd, (float(spec["hi"]) - mean) / sd
        except (KeyError, TypeError, ValueError):
            raise EffectSpecError(f"effect spec 'channel' of shape {shape!r} lacks a numeric 'lo' or 'hi'") from None
    if by:
        try:
            load_abs = float(spec["load_abs"])
        except (KeyError, TypeError, ValueError):
            raise EffectSpecError("effect spec 'channel' with an interaction lacks a numeric 'load_abs'") from None
        if not load_abs > 0:
            raise EffectSpecError(f"effect spec 'channel': load_abs {load_abs} is not positive")
    code = code + SHAPES.index(shape) * len(FORMS) + (BY_LOAD if by else 0)
    return [float(code), mean, sd, z_lo, z_hi, load_abs]


# ---------------------------------------------------------------------------
# shared helpers (the plain-float forms of l1b2.predictor.effects.base's)
# ---------------------------------------------------------------------------

def scaled1(x, lo, hi):
    """``x`` mapped from [lo, hi] to [0, 1] and clipped (0 when the range is empty): ``base.scaled``."""
    if hi > lo:
        return min(max((x - lo) / (hi - lo), 0.0), 1.0)
    return 0.0


def knot(i, n_inner):
    """Knot ``i`` of the clamped cubic B-spline on [0, 1] with ``n_inner`` equally spaced inner knots."""
    if i <= 3:
        return 0.0
    if i >= n_inner + 4:
        return 1.0
    return (i - 3) * (1.0 / (n_inner + 1))


def bspline1(j, k, u, n_inner):
    """Cox-de Boor: the B-spline ``j`` of degree ``k`` at ``u`` (half-open spans, 0/0 taken as 0)."""
    t0 = knot(j, n_inner)
    t1 = knot(j + 1, n_inner)
    if k == 0:
        if t0 <= u < t1:
            return 1.0
        return 0.0
    tk = knot(j + k, n_inner)
    tk1 = knot(j + k + 1, n_inner)
    out = 0.0
    if tk > t0:
        out = out + (u - t0) / (tk - t0) * bspline1(j, k - 1, u, n_inner)
    if tk1 > t1:
        out = out + (tk1 - u) / (tk1 - t1) * bspline1(j + 1, k - 1, u, n_inner)
    return out


def bspline_force(u, n_inner, phi):
    """``bspline_basis(u, n_inner) @ phi`` at one sample (the cubic basis, ``u`` clipped)."""
    uc = min(max(u, 0.0), BSPLINE_U_MAX)
    nb = int(n_inner + 4)
    out = 0.0
    for j in range(nb):
        out = out + bspline1(j, 3, uc, n_inner) * phi[j]
    return out


# ---------------------------------------------------------------------------
# the named families
# ---------------------------------------------------------------------------

def thermal_drift_force(x, q, phi):
    g = x[SIG_V0] / V_REF
    return g * bspline_force(scaled1(x[SIG_T], q[0], q[1]), q[2], phi)


def thermal_drift_t_force(x, q, phi):
    g = x[SIG_V0] / V_REF
    dT = x[SIG_TEMP] - q[0]
    return g * dT * phi[0] + g * dT ** 2 / 10.0 * phi[1]


def direction_asymmetry_force(x, q, phi):
    d = x[SIG_D]
    return d * (x[SIG_V0] / V_REF) * phi[0] + d * phi[1]


def bar_waviness_force(x, q, phi):
    g = x[SIG_V0] / V_REF
    ph = 2 * math.pi * x[SIG_S] / q[0]
    u = x[SIG_D] * x[SIG_VB] / SPEED_REF
    c = math.cos(ph)
    s = math.sin(ph)
    return (c * phi[0] + s * phi[1] + g * c * phi[2] + g * s * phi[3] + u * c * phi[4] + u * s * phi[5]
            + math.cos(2 * ph) * phi[6] + math.sin(2 * ph) * phi[7])


def local_defect_force(x, q, phi):
    return math.exp(-0.5 * ((x[SIG_S] - q[0]) / q[1]) ** 2) * phi[0]


def load_path_friction_force(x, q, phi):
    return -G_M_S2 * abs(x[SIG_LOAD]) * phi[0]


def drive_saturation_force(x, q, phi):
    g = x[SIG_V0] / V_REF
    return g ** 2 * phi[0] + g ** 3 * phi[1]


def speed_dependent_friction_force(x, q, phi):
    vp = x[SIG_D] * x[SIG_VB]
    return -vp / SPEED_REF * phi[0] + -vp * abs(vp) / SPEED_REF ** 2 * phi[1]


def inertia_mismatch_force(x, q, phi):
    return -q[0] * x[SIG_D] * x[SIG_AB] * phi[0]


def voltage_slope_force(x, q, phi, regressor):
    """``load_slope_voltage`` (``regressor`` the load) and ``damping_voltage`` (the speed): one form,
    ``-(d r) dv``, ``r`` the load's weight ``m g`` or the speed over ``SPEED_REF``, ``dv = (V0 - V_ref)/V_REF``."""
    dv = (x[SIG_V0] - q[0]) / V_REF
    if regressor == SIG_LOAD:
        return -(x[SIG_D] * x[SIG_LOAD] * G_M_S2) * dv * phi[0]
    return -(x[SIG_D] * x[SIG_VB]) / SPEED_REF * dv * phi[0]


def position_load_force(x, q, phi):
    w = x[SIG_D] * x[SIG_LOAD] * G_M_S2
    xp = 2 * scaled1(x[SIG_S], q[0], q[1]) - 1
    return -w * xp * phi[0] + -w * xp ** 2 * phi[1]


# ---------------------------------------------------------------------------
# the generic terms (l1b2.predictor.effects.generic)
# ---------------------------------------------------------------------------

def pair_width(reg):
    """Columns of a regressor's pair factor: 1 (direction), else 2 (linear and quadratic)."""
    if reg == 2:
        return 1
    return 2


def pair_factor(reg, j, x, q, o):
    """Column ``j`` of the pair factor of regressor ``reg`` (``generic._factor``); ranges at ``q[o:]``."""
    u = 0.0
    if reg == 0:
        u = 2 * scaled1(x[SIG_T], q[o + R_T_LO], q[o + R_T_HI]) - 1
    elif reg == 1:
        u = 2 * scaled1(x[SIG_S], q[o + R_S_LO], q[o + R_S_HI]) - 1
    elif reg == 2:
        return x[SIG_D]
    elif reg == 3:
        u = x[SIG_D] * x[SIG_LOAD] / q[o + R_LOAD_ABS]
    elif reg == 4:
        u = 2 * scaled1(x[SIG_V0], q[o + R_V_LO], q[o + R_V_HI]) - 1
    elif reg == 5:
        u = 2 * scaled1(abs(x[SIG_VB]), q[o + R_VB_LO], q[o + R_VB_HI]) - 1
    else:
        return math.nan
    if j == 0:
        return u
    return u ** 2


def smooth_force(x, q, phi):
    """``generic._single`` of the regressor ``q[0]`` @ phi (ranges at ``q[1:]``)."""
    reg = int(q[0])
    if reg == 0:
        return bspline_force(scaled1(x[SIG_T], q[1 + R_T_LO], q[1 + R_T_HI]), 6, phi)
    if reg == 1:
        return bspline_force(scaled1(x[SIG_S], q[1 + R_S_LO], q[1 + R_S_HI]), q[1 + R_N_INNER], phi)
    if reg == 2:
        return x[SIG_D] * phi[0]
    if reg == 3:
        m = x[SIG_LOAD] / q[1 + R_LOAD_ABS]
        dm = x[SIG_D] * m
        return dm * phi[0] + abs(m) * phi[1] + dm ** 2 * phi[2]
    if reg == 4:
        u = 2 * scaled1(x[SIG_V0], q[1 + R_V_LO], q[1 + R_V_HI]) - 1
        return u * phi[0] + u ** 2 * phi[1]
    if reg == 5:
        return bspline_force(scaled1(abs(x[SIG_VB]), q[1 + R_VB_LO], q[1 + R_VB_HI]), 4, phi)
    if reg == 6:
        acc = x[SIG_D] * x[SIG_AB] * q[1 + R_M_S]
        return acc * phi[0] + abs(acc) * phi[1]
    return bspline_force(scaled1(x[SIG_TEMP], q[1 + R_TEMP_LO], q[1 + R_TEMP_HI]), 4, phi)


def smooth_pair_force(x, q, phi):
    """``generic.SmoothPair.features`` @ phi: the products of the two regressors' factors (ranges at ``q[2:]``)."""
    ra = int(q[0])
    rb = int(q[1])
    wa = int(pair_width(ra))
    wb = int(pair_width(rb))
    out = 0.0
    for j in range(wa):
        for k in range(wb):
            out = out + pair_factor(ra, j, x, q, 2) * pair_factor(rb, k, x, q, 2) * phi[j * wb + k]
    return out


# ---------------------------------------------------------------------------
# a logged channel or a run-level signal of an input (l1b2.predictor.effects.channels)
# ---------------------------------------------------------------------------

def input_signal(x, sig):
    """The sample's value of the signal of index ``sig``: the FMU's input giving a channel's or a run-level
    signal (for a run-level signal its current value, the run's value when the input is constant within a run)."""
    return x[sig]


def channel_force(x, q, phi):
    """``Channel.features`` @ phi: ``z`` = (input - mean)/sd (``q[0]`` the input, ``q[2:4]`` mean and sd) in its
    shape (``z phi[0]``; ``q[1]`` >= ``QUADRATIC``: ``zc phi[0] + (zc^2 - 1) phi[1]``, >= ``ODD``:
    ``zc phi[0] + (zc^3 - 3 zc) phi[1]``, ``zc`` = ``z`` clipped to ``q[4:6]``) times the form's factor (the code
    less its offsets: -1, ``V0/V_REF``, ``d``, for the inertia form ``-q[7] d a_base``, for the damping form
    ``-d v_base / SPEED_REF``); with ``q[1]`` >=
    ``BY_LOAD``, plus the same columns times ``|load| / q[6]`` on the next parameters; the inertia form adds its
    constant, the next parameter (the mass change at the channel's mean)."""
    z = (input_signal(x, int(q[0])) - q[2]) / q[3]
    form = int(q[1])
    u = 0.0
    by = 0
    if form >= BY_LOAD:
        form = form - BY_LOAD
        by = 1
        u = abs(x[SIG_LOAD]) / q[6]
    n = int(1)   # an int: it indexes phi
    b1 = z
    b2 = 0.0
    if form >= ODD:
        form = form - ODD
        n = int(2)
        b1 = min(max(z, q[4]), q[5])
        b2 = b1 * b1 * b1 - 3.0 * b1
    elif form >= QUADRATIC:
        form = form - QUADRATIC
        n = int(2)
        b1 = min(max(z, q[4]), q[5])
        b2 = b1 * b1 - 1.0
    g = b1 * phi[0]
    if n > 1:
        g = g + b2 * phi[1]
    if by == 1:
        gu = b1 * phi[n]
        if n > 1:
            gu = gu + b2 * phi[n + 1]
        g = g + u * gu
    if form == FORM_FRICTION:
        return -g
    if form == FORM_FORCE_FACTOR:
        return x[SIG_V0] / V_REF * g
    if form == FORM_INERTIA:
        return -q[7] * x[SIG_D] * x[SIG_AB] * (g + phi[n])
    if form == FORM_DAMPING:
        return -(x[SIG_D] * x[SIG_VB]) / SPEED_REF * g
    return x[SIG_D] * g


def run_level_force(x, q, phi):
    """``RunLevel.features`` @ phi: ``z (a V0/V_REF + b + c g d m)``, ``z`` = (c - mean)/sd of the input ``q[0]``
    less its centre ``q[5]``, transformed by ``q[1]`` (none, times the direction, its size, its square less ``q[6]``
    times it); ``q[4]``
    the column a reduced form leaves out (:data:`RL_GAIN`, :data:`RL_OFFSET`, :data:`RL_LOAD`; -1: none), whose
    parameter it does not have."""
    c = input_signal(x, int(q[0])) - q[5]
    tr = int(q[1])
    if tr == TR_DRIVE:
        c = c * x[SIG_D]
    elif tr == TR_ABS:
        c = abs(c)
    elif tr == TR_SQUARE:
        c = c * c - q[6] * c
    z = (c - q[2]) / q[3]
    g = x[SIG_V0] / V_REF * z
    w = G_N_PER_KG * x[SIG_D] * x[SIG_LOAD] * z
    drop = int(q[4])
    if drop == RL_GAIN:
        return z * phi[0] + w * phi[1]
    if drop == RL_OFFSET:
        return g * phi[0] + w * phi[1]
    if drop == RL_LOAD:
        return g * phi[0] + z * phi[1]
    return g * phi[0] + z * phi[1] + w * phi[2]


def effect_force(kind, x, q, phi):
    """The force [N] of one effect of kind index ``kind`` (:data:`KERNEL_KINDS`) at one sample."""
    if kind == K_THERMAL:
        return thermal_drift_force(x, q, phi)
    if kind == K_THERMAL_T:
        return thermal_drift_t_force(x, q, phi)
    if kind == K_DIRECTION:
        return direction_asymmetry_force(x, q, phi)
    if kind == K_BAR:
        return bar_waviness_force(x, q, phi)
    if kind == K_DEFECT:
        return local_defect_force(x, q, phi)
    if kind == K_LOAD_PATH:
        return load_path_friction_force(x, q, phi)
    if kind == K_SATURATION:
        return drive_saturation_force(x, q, phi)
    if kind == K_DRAG:
        return speed_dependent_friction_force(x, q, phi)
    if kind == K_INERTIA:
        return inertia_mismatch_force(x, q, phi)
    if kind == K_LOAD_V:
        return voltage_slope_force(x, q, phi, SIG_LOAD)
    if kind == K_DAMPING_V:
        return voltage_slope_force(x, q, phi, SIG_VB)
    if kind == K_POSITION_LOAD:
        return position_load_force(x, q, phi)
    if kind == K_SMOOTH:
        return smooth_force(x, q, phi)
    if kind == K_PAIR:
        return smooth_pair_force(x, q, phi)
    if kind == K_CHANNEL:
        return channel_force(x, q, phi)
    if kind == K_RUN_LEVEL:
        return run_level_force(x, q, phi)
    return math.nan


def kernel_family() -> dict:
    """Every kernel of this module by name (what the translator turns into C; ``effect_force`` the entry)."""
    names = ("scaled1", "knot", "bspline1", "bspline_force", "thermal_drift_force", "thermal_drift_t_force",
             "direction_asymmetry_force", "bar_waviness_force", "local_defect_force", "load_path_friction_force",
             "drive_saturation_force", "speed_dependent_friction_force", "inertia_mismatch_force",
             "voltage_slope_force", "position_load_force", "pair_width", "pair_factor", "smooth_force",
             "smooth_pair_force", "input_signal", "channel_force", "run_level_force", "effect_force")
    g = globals()
    return {n: g[n] for n in names}
