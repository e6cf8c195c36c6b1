"""A TEST run that repeats TRAIN samples (decision 0124): refused when at least half its samples are TRAIN's.

A sample is TRAIN's when a TRAIN sample has the same time stamp, position and (both measured) speed
(:func:`l1b2.data.coverage.shared_run`). Each case is a small file in ``tmp_path`` read as identify and close-loop
read it (:func:`l1b2.workflows.load_train_test`); references: the shared rows counted by hand.
"""

from __future__ import annotations

import numpy as np
import pytest
from l1b2.data.coverage import SHARED_SHARE, shared_run
from l1b2.data.measurements import load_measurements
from l1b2.errors import DataFormatError
from l1b2.workflows import load_train_test

HEADER = "time_s,run,position_m,voltage_V,direction,load_kg,speed_m_s"
N = 8


def rows(t0=0.0, runs=(1, 2, 3, 4), speed_noise=0.0, position_noise=0.0, seed=0) -> list[list[float]]:
    """N samples per run at 1 kHz, 0.1 m/s forward in odd runs, backward in even ones; the clock runs on. The speed
    (and position) with Gaussian noise of ``speed_noise`` m/s (``position_noise`` m) when given."""
    rng = np.random.default_rng(seed)
    out, t = [], t0
    for r in runs:
        d = 1 if r % 2 else -1
        for k in range(N):
            x = d * 1e-4 * (k + 1) + position_noise * rng.standard_normal()
            out.append([round(t, 6), r, x, 100.0, d, 0.0, d * 0.1 + speed_noise * rng.standard_normal()])
            t += 0.001
        t += 0.5
    return out


def write(tmp_path, table, name, speed=True):
    lines = [HEADER if speed else HEADER.rsplit(",", 1)[0]]
    lines += [",".join(repr(v) if isinstance(v, float) else str(v) for v in (r if speed else r[:-1])) for r in table]
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def refused(train, test) -> DataFormatError:
    with pytest.raises(DataFormatError) as info:
        load_train_test(train, test)
    assert info.value.column == "run" and test.name in str(info.value), str(info.value)
    return info.value


def test_a_test_run_cut_from_a_train_run_is_refused_naming_file_run_and_first_shared_row(tmp_path):
    train_rows = rows(speed_noise=1e-3)
    train = write(tmp_path, train_rows, "train.csv")
    # a recording of its own first, at rest for 12 samples before its onset (cut on reading: the frame's rows are
    # no longer the file's), then samples 3-7 of TRAIN run 2
    rest = [[round(0.1 + 0.001 * k, 6), 7, 0.0, 100.0, 1, 0.0, 0.0] for k in range(12)]
    own = [[round(0.112 + 0.001 * k, 6), 7, 1e-4 * (k + 1), 100.0, 1, 0.0, 0.1 + 1e-3 * (-1) ** k] for k in range(N)]
    piece = [[*r[:1], 8, *r[2:]] for r in train_rows[N + 2:N + 7]]
    test = write(tmp_path, rest + own + piece, "piece.csv")
    assert load_measurements(test).meta["rest_before_onset"]["samples"] == 11     # not vacuous: rows were cut
    exc = refused(train, test)
    assert "TEST run 8 shares 5 of its 5 samples with TRAIN run 2" in str(exc)
    assert exc.row == 12 + N + 1                                                # the piece's first row in the file
    # the same piece under TRAIN's own run id, alone: the same answer, the file's first row
    exc = refused(train, write(tmp_path, [[*r[:1], 2, *r[2:]] for r in train_rows[N + 2:N + 7]], "alone.csv"))
    assert "TEST run 2 shares 5 of its 5 samples with TRAIN run 2" in str(exc) and exc.row == 1
    # the whole run: it is the TRAIN run
    assert "TEST run 3 is TRAIN run 3 (the same recorded samples)" in str(
        refused(train, write(tmp_path, train_rows[2 * N:3 * N], "whole.csv")))


def test_a_test_run_re_exported_with_rows_dropped_is_refused(tmp_path):
    train_rows = rows(speed_noise=1e-3)
    train = write(tmp_path, train_rows, "train.csv")
    run4 = train_rows[3 * N:4 * N]
    dropped = [r for i, r in enumerate(run4) if i not in (0, 5)]                 # its first and sixth rows lost
    exc = refused(train, write(tmp_path, dropped, "dropped.csv"))
    assert "TEST run 4 shares 6 of its 6 samples with TRAIN run 4" in str(exc) and exc.row == 1


def test_the_threshold_is_half_the_run(tmp_path):
    # reference: a TEST run of N = 8 samples whose first k are TRAIN's (a clock restarted at 0, the same samples)
    # and whose others are its own (another speed): refused from k = 4 = SHARED_SHARE * 8
    assert SHARED_SHARE == 0.5
    train_rows = rows(speed_noise=1e-3)
    train = write(tmp_path, train_rows, "train.csv")
    other = rows(runs=(1,), speed_noise=1e-3, seed=5)
    for k in (1, 3, 4, 8):
        mixed = train_rows[:k] + other[k:N]
        path = write(tmp_path, mixed, f"k{k}.csv")
        found = shared_run(load_measurements(train), load_measurements(path))
        if k < 4:
            assert found is None
            assert load_train_test(train, path)[1].runs == [1]
        else:
            assert (found.run, found.train_run, found.shared, found.samples, found.row) == (1, 1, k, N, 1)
            assert found.same == (k == N)


def test_two_simulated_runs_of_one_plan_are_accepted(tmp_path):
    # the same plan twice: equal stamps and positions, each measured speed with its own noise: no sample shared
    train = write(tmp_path, rows(speed_noise=1e-3, seed=1), "sim1.csv")
    test = write(tmp_path, rows(speed_noise=1e-3, seed=2), "sim2.csv")
    assert shared_run(load_measurements(train), load_measurements(test)) is None
    assert load_train_test(train, test)[1].runs == [1, 2, 3, 4]


def test_a_derived_speed_file_is_judged_on_stamps_and_positions(tmp_path):
    train_rows = rows(speed_noise=1e-3)
    train = write(tmp_path, train_rows, "train.csv")
    # cut from TRAIN, exported without the speed (derived from position on reading): refused
    piece = [r for i, r in enumerate(train_rows[N:2 * N]) if i != 3]
    exc = refused(train, write(tmp_path, piece, "derived.csv", speed=False))
    assert "TEST run 2 shares 7 of its 7 samples with TRAIN run 2" in str(exc)
    # a simulation of the same plan whose positions carry their own noise, speed derived: accepted
    resim = write(tmp_path, rows(position_noise=2e-6, seed=3), "resim.csv", speed=False)
    assert load_train_test(train, resim)[1].runs == [1, 2, 3, 4]
    assert load_train_test(write(tmp_path, rows(position_noise=2e-6, seed=4), "t2.csv", speed=False), resim)


def test_the_check_is_vectorised_over_a_large_file():
    # reference: one shared run among 5000 disjoint ones is found, the disjoint files pass (a loose time bound)
    import time

    import pandas as pd
    from l1b2.data.measurements import Measurements
    n_runs, n = 5000, 40
    t = np.arange(n_runs * n) * 1e-3
    frame = pd.DataFrame({"time_s": t, "run": np.repeat(np.arange(n_runs), n), "position_m": np.tile(
        np.arange(n) * 1e-4, n_runs), "voltage_V": 100.0, "direction": 1, "load_kg": 0.0,
        "speed_m_s": 0.1 + 1e-3 * np.sin(t * 7e3)})
    train = Measurements(frame, {}, "train.csv")
    later = frame.assign(time_s=t + 1e4)
    start = time.process_time()
    assert shared_run(train, Measurements(later, {}, "test.csv")) is None
    cut = pd.concat([later.iloc[:n * 10], frame.iloc[n * 20 + 3:n * 21]]).reset_index(drop=True)
    found = shared_run(train, Measurements(cut, {}, "test.csv"))
    assert time.process_time() - start < 5.0
    assert (found.run, found.train_run, found.shared, found.row) == (20, 20, n - 3, n * 10 + 1)
