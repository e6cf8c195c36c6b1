"""Valid but unusual rig data in the close loop (decision 0130): columns a real rig logs that carry nothing new.

Fast unit tests on small synthetic arrays.
"""

import numpy as np
from l1b2.closeloop import runlevel as rl


def _deviations(cause, seed=5):
    """Run deviations ``(gain, offset)`` whose offset follows ``cause`` (56 runs, the events test's noise)."""
    rng = np.random.default_rng(seed)
    n = len(cause)
    S = np.array([[4e-4, 0.0], [0.0, 0.01]])
    z = (cause - cause.mean()) / cause.std()
    theta = (np.array([1.0, 0.0]) + np.outer(z, [0.0, 0.3])
             + rng.multivariate_normal([0, 0], np.diag([1e-4, 4e-3]), n) + rng.multivariate_normal([0, 0], S, n))
    return rl.RunDeviations(np.arange(n), theta, np.repeat(S[None], n, axis=0), np.full(n, 500))


def test_a_logged_copy_of_the_drive_amplitude_is_dominated_by_the_plans_own_column():
    """An amplifier's read-back logged beside the plan (``amp_monitor_V = V0 / 100 + 0.05``) carries the same run
    values as ``voltage_V``: each is nested in the other, so neither has evidence beyond the other. The plan's input
    is named, whichever is listed first; between two logged twins the first listed stays the winner."""
    V = np.tile([220.0, 255.0, 290.0, 324.0], 14)
    dev = _deviations(V)
    monitor = {"channel": "amp_monitor_V", "transform": "none", "values": V / 100 + 0.05}
    plan = {"channel": "voltage_V", "transform": "none", "values": V}
    for sigs in ([monitor, plan], [plan, monitor]):
        got = rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)
        by = {e.channel: e for e in got}
        assert by["voltage_V"].significant and by["amp_monitor_V"].significant
        assert by["voltage_V"].dominated_by is None and by["amp_monitor_V"].dominated_by == "voltage_V"
        assert got[0].channel == "voltage_V"
    twin = {"channel": "amp_monitor_b_V", "transform": "none", "values": V / 100 + 0.05}
    by = {e.channel: e for e in rl.signal_evidence(dev, [monitor, twin], alpha=0.01, k=4, seed=0)}
    assert by["amp_monitor_V"].dominated_by is None and by["amp_monitor_b_V"].dominated_by == "amp_monitor_V"


def test_the_plan_preference_only_breaks_ties_of_signals_nested_in_each_other():
    """A logged channel that explains the runs better than a correlated plan input (not nested in it) keeps its
    place: the preference for the plan's column decides only between signals of the same run values."""
    rng = np.random.default_rng(2)
    V = np.tile([220.0, 255.0, 290.0, 324.0], 14)
    cause = V / 100 + 0.3 * rng.normal(size=len(V))        # follows the drive amplitude, and more (r ~ 0.8)
    dev = _deviations(cause)
    sigs = [{"channel": "voltage_V", "transform": "none", "values": V},
            {"channel": "heatsink_C", "transform": "none", "values": 25 + cause}]
    by = {e.channel: e for e in rl.signal_evidence(dev, sigs, alpha=0.01, k=4, seed=0)}
    assert by["heatsink_C"].dominated_by is None and by["voltage_V"].dominated_by == "heatsink_C"
    zs = [np.asarray(s["values"], float) for s in sigs]
    assert rl.dominated_signals(dev, [True, True], zs, 0.01, plan=[True, False]) == \
        rl.dominated_signals(dev, [True, True], zs, 0.01) == [1, None]


def test_a_noise_update_on_a_blown_up_residual_gives_nan_without_a_warning():
    """A trial step whose free run blew up gives NaN residuals (a run cut short after a few samples): the noise
    model's update returns NaN for its change (the caller rejects the step) and the fallback variance, and says
    nothing on stderr (no numpy all-NaN warning); finite residuals keep ``nanmax`` / ``nanmedian``'s values."""
    import warnings
    from l1b2.ident.noise import NoiseModel
    run = np.repeat(np.arange(3), 4)
    common, per_run = NoiseModel(run, 3, "common"), NoiseModel(run, 3, "per_run")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(common.update_R(np.full(12, np.nan)))
        assert per_run.update_R(np.full(12, np.nan)) == 1.0     # no run's variance: the floor 1e-300 everywhere
    assert np.all(per_run.R == 1e-300)
    nm = NoiseModel(run, 4, "per_run")                      # a run without samples: its variance is NaN, skipped
    r = np.array([1.0, -1, 1, -1, 2, -2, 2, -2, 0.1, -0.1, 0.1, -0.1])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        change = nm.update_R(r)
    var = np.array([1.0, 4.0, 0.01])
    med = np.median(var)
    np.testing.assert_allclose(nm.R, list(np.maximum(var, 0.1 * med)) + [med])
    assert change == np.max(np.abs(nm.R - 1.0))


def test_the_baselines_parameters_train_does_not_determine_are_named_in_a_warning():
    """A TRAIN at one load (or one drive amplitude) leaves a direction of the baseline's parameters without a
    standard error: the close loop's warnings (CLI and report.md) name the varied ones; pinned parameters
    (``vary`` false) and determined ones are not named, and ordinary data give no line."""
    from l1b2.closeloop.report import loop_check_lines, undetermined_line
    params = {"c_r": {"value": 244.8, "vary": True, "identifiable": False},
              "sigma": {"value": 47.5, "vary": False, "identifiable": False},
              "alpha_0": {"value": 5.6, "vary": True, "identifiable": False},
              "alpha_1": {"value": -0.03, "vary": True, "identifiable": True}}
    line = undetermined_line(params)
    assert "c_r, alpha_0 " in line and "sigma" not in line and "alpha_1" not in line
    ordinary = {k: dict(v, identifiable=True) for k, v in params.items()}
    assert undetermined_line(ordinary) == "" and undetermined_line({}) == "" and undetermined_line(None) == ""
    assert loop_check_lines({"channel_ranges": []}, ordinary) == []
    assert loop_check_lines({}, params) == [line]
