"""bench/runlevel_null_size.py: its null draws and its two references of one Wald statistic."""

import numpy as np
import pytest


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("runlevel_null_size")


def test_a_draw_pairs_opposite_loads_and_a_signal_over_two_decades(bench):
    dev, z = bench.draw(np.random.default_rng(0), 40, "t3")
    assert dev.theta.shape == (40, 2) and dev.cov.shape == (40, 2, 2)
    assert np.allclose(dev.load[0::2], -dev.load[1::2]) and set(np.abs(dev.load)) <= {0.2, 0.5, 1.0}
    assert np.all(np.linalg.eigvalsh(dev.cov) > 0)
    assert 1.0 <= z.min() and z.max() <= 100.0


def test_the_f_reference_of_one_coefficient_is_the_two_sided_t_test_and_tends_to_chi_square(bench):
    from scipy import stats
    for t, n, k in ((2.3, 20, 4), (3.1, 12, 5), (0.4, 56, 5)):
        p_chi2 = stats.chi2.sf(t * t, 1)
        assert bench.f_reference(p_chi2, 1, n, k) == pytest.approx(2 * stats.t.sf(t, n - k), rel=1e-9)
    assert bench.f_reference(1e-3, 3, 10 ** 7, 5) == pytest.approx(1e-3, rel=1e-3)
    assert bench.f_reference(1e-3, 3, 56, 5) > 2e-3         # a few dozen runs: a heavier tail than chi-square


def test_the_f_reference_never_rejects_more_than_chi_square_of_the_same_statistic(bench, capsys):
    bench.main(["--runs", "16", "--draws", "60", "--seed", "3"])
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 2
    for line in lines:
        f, chi = (np.array(part.split()[-3:], float) for part in line.split("|"))
        assert np.all(f <= chi) and np.all(np.diff(f) >= 0)
