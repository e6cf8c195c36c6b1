"""Close the loop on the realistic motor variant (issue 11) with two undeclared effects injected at once.

The checks are the realistic world's (``tests/realistic_cases.py``): both injected regressors among the first
three traced, and on TEST ``a^2 <= b0^2 + (b^2 - b0^2)/4`` (b: baseline, a: extended, b0: the baseline of the same
seed without the effects). A module of its own so that ``make test``'s two workers, which take whole modules, can
run it beside the single effects (``tests/conftest.py``, ``COSTLY_FIRST``). The pair the loop is known to miss is a
strict xfail with its measured reason, so that a pass is noticed.
"""

import pytest
from realistic_cases import check_effects, known_miss, machine_borderline, run_case

PAIRS = [(("pulley_friction", "drive_saturation"), 5),
         pytest.param(("direction_asymmetry", "thermal_drift"), 6, marks=known_miss("time not traced")),
         (("bar_waviness", "pulley_friction"), 7),
         pytest.param(("bar_bump", "direction_asymmetry"), 9, marks=machine_borderline(
             "bar_waviness's named reading withdrawn on some BLAS builds, position traced fourth (0129)")),
         (("drive_saturation", "bar_waviness"), 10)]


@pytest.mark.slow    # make test-slow (decision 0100)
@pytest.mark.parametrize("effects,seed", PAIRS)
def test_realistic_two_effects(effects, seed, record_property):
    res, truth = run_case(effects, seed)
    check_effects(res, truth, seed, 3, record_property)
