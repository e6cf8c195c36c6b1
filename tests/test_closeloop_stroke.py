"""The position sensor's gain from the recorded travel between the end stops (``l1b2.closeloop.chain.stroke_gain``).

Fast unit tests against travel written out here: a gain taken from a run that stalled short of the far stop, a
travel measured on one end only, a slope of the channel on the gain instead of the gain on the channel, or a
dropped Bonferroni correction over the channels fails one of them.
"""

import numpy as np
import pandas as pd
import pytest
from l1b2.closeloop import chain


def _runs(travel, channels, s0=-0.021):
    """One run per travel [m] from ``s0`` (5 samples), with per-run channel values (``{name: values}``)."""
    rows = []
    for k, tr in enumerate(travel):
        row = {"time_s": 2.0 * k + 0.1 * np.arange(5), "run": k + 1, "position_m": s0 + tr * np.linspace(0, 1, 5)}
        row.update({name: float(v[k]) for name, v in channels.items()})
        rows.append(pd.DataFrame(row))
    return pd.concat(rows, ignore_index=True)


def test_a_gain_that_follows_a_channel_is_found_from_the_full_traverses_only():
    rng = np.random.default_rng(1)
    n, g = 30, -0.004                                       # gain -0.4 %/K about 25 degC
    T = 25 + 3 * rng.standard_normal(n)
    travel = 0.042 * (1 + g * (T - 25))
    travel[7] = 0.025                                         # stalled short of the far stop: not a full traverse
    other = rng.standard_normal(n)
    out = chain.stroke_gain(_runs(travel, {"T": T, "other": other}), ["T", "other"], alpha=0.01)
    full = np.arange(n) != 7
    rel = travel[full] / np.median(travel[full]) - 1
    assert out["full_runs"] == n - 1
    assert out["gain_sd_rel"] == pytest.approx(np.std(rel))
    assert out["gain_range_rel"] == pytest.approx(np.ptp(rel))
    assert out["channel"] == "T" and out["significant"] and out["r"] < -0.999
    assert out["slope_per_unit"] == pytest.approx(g * 0.042 / np.median(travel[full]), rel=1e-9)


def test_a_fixed_stroke_shows_no_gain_and_a_weak_one_is_judged_over_all_channels_tested():
    T = np.linspace(20, 30, 12)
    out = chain.stroke_gain(_runs(np.full(12, 0.042), {"T": T}), ["T"])
    assert out["gain_sd_rel"] == 0.0 and out["channel"] is None and not out["significant"]
    rng = np.random.default_rng(5)
    noise = rng.standard_normal(12)
    travel = 0.042 * (1 + 1e-4 * noise)
    chans = {f"c{i}": rng.standard_normal(12) for i in range(4)}
    chans["c0"] = noise + 1.6 * rng.standard_normal(12)     # weakly related to the gain
    out = chain.stroke_gain(_runs(travel, chans), list(chans), alpha=0.05)
    from scipy import stats
    p = {name: stats.linregress(c, travel / np.median(travel) - 1).pvalue for name, c in chans.items()}
    best = min(p, key=p.get)
    assert out["channel"] == best and out["p_value"] == pytest.approx(p[best])
    assert 0.05 / 4 < p[best] < 0.05 and not out["significant"]     # significant alone, not among four
