"""The pure-slip family with a drive-frequency response: its start, the response's bounds and Jacobian, recovery."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from l1b2.ident.reduced import slip_sigma_start


def test_slip_sigma_start_puts_the_median_slip_ratio_at_k_ref():
    # reference: k = sigma v' / (pi B'(s) V0) written out; B'(x) = 0.004 + 0.001 x (Legendre), x = (s - 0.001)/0.02;
    # samples moving backwards (d v < 0), masked out or without drive (V0 = 0) do not count
    rng = np.random.default_rng(0)
    n = 201
    s = rng.uniform(-0.02, 0.02, n)
    V0 = rng.choice([220.0, 324.0], n)
    d = np.ones(n)
    v = rng.uniform(0.05, 0.3, n)
    mask = np.ones(n, bool)
    d[:20] = -1.0            # moving against the drive direction: v' < 0
    mask[20:40] = False
    V0[40:50] = 0.0
    data = SimpleNamespace(s=s, V0=V0, d=d, v=v, mask=mask)
    Bp = 0.004 + 0.001 * (s - 0.001) / 0.02
    use = slice(50, None)
    ratio = v[use] / (np.pi * Bp[use] * V0[use])
    got = slip_sigma_start(data, [0.004, 0.001], 0.001, 0.02, k_ref=0.4)
    assert got == pytest.approx(0.4 / np.median(ratio), rel=1e-12)
    k = got * ratio
    assert np.median(k) == pytest.approx(0.4, rel=1e-12)
    assert slip_sigma_start(SimpleNamespace(s=s, V0=V0, d=-d, v=np.abs(v), mask=mask & (d < 0) & False),
                            [0.004], 0.0, 0.02) is None
