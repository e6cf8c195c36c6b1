"""bench/crowded_rig.py: the bystander channels it adds to an audit case's files, against the formulas written out."""

import numpy as np
import pandas as pd
import pytest


@pytest.fixture(scope="module")
def crowded(load_bench):
    return load_bench("crowded_rig")


def test_bystanders_are_log_uniform_over_two_decades_from_their_own_stream(crowded):
    v = crowded.bystander_values(3, 2, 5000)
    rng = np.random.default_rng([3, 231, 2])
    assert np.allclose(v, np.round(np.exp(rng.uniform(np.log(1.0), np.log(100.0), 5000)), 3))
    assert 1.0 <= v.min() and v.max() <= 100.0
    # log-uniform: a quarter of the values in each half-decade quarter of the log range
    counts = np.histogram(np.log10(v), bins=[0, 0.5, 1.0, 1.5, 2.0])[0] / len(v)
    assert np.allclose(counts, 0.25, atol=0.03)
    assert not np.allclose(v, crowded.bystander_values(3, 1, 5000))     # each bystander its own stream
    assert np.array_equal(v[:10], crowded.bystander_values(3, 2, 10))   # a run's value does not depend on the count


def test_a_crowded_part_keeps_its_columns_and_holds_each_bystander_constant_in_a_run(crowded):
    df = pd.DataFrame({"time_s": np.arange(9.0), "run": [2, 2, 2, 5, 5, 5, 7, 7, 7], "speed_m_s": np.ones(9)})
    out = crowded.crowded(df, 1, 3, 8)
    assert list(out.columns) == ["time_s", "run", "speed_m_s", "bystander1_mV", "bystander2_mV", "bystander3_mV"]
    assert out[df.columns].equals(df)
    for j in (1, 2, 3):
        per_run = crowded.bystander_values(1, j, 8)
        assert np.array_equal(out[f"bystander{j}_mV"].to_numpy(), per_run[df["run"].to_numpy() - 1])
    assert (out.groupby("run")["bystander1_mV"].nunique() == 1).all()
