"""The run settings' controls (``bench/run_setting_controls.py``): the decoys' readings against their formulas
written out here, their draws, the files made from the clean case's and the pass rule."""

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import run_setting_controls as rc  # noqa: E402


def _frame(first_run=3, n=6):
    return pd.DataFrame({"run": np.repeat([first_run, first_run + 1], n // 2),
                         "speed_m_s": np.linspace(-0.2, 0.2, n), "position_m": np.linspace(-0.021, 0.021, n)})


def test_the_zeros_are_drawn_per_run_in_their_ranges_from_the_kinds_stream():
    for kind, top in (("tacho_offset_decoy", 0.05), ("cell_zero_decoy", 0.3)):
        z = rc.zeros(kind, 2)
        assert z.shape == (72,) and np.all(np.abs(z) <= top) and np.ptp(z) > top
        want = np.random.default_rng([2, 180, rc.KINDS.index(kind)]).uniform(-top, top, 72)
        np.testing.assert_array_equal(z, want)
    assert not np.array_equal(rc.zeros("tacho_offset_decoy", 1), rc.zeros("tacho_offset_decoy", 2))


def test_the_tachometer_reads_k_v_plus_its_runs_zero_and_noise_to_a_tenth_of_a_millivolt():
    df = _frame()
    z = rc.zeros("tacho_offset_decoy", 1)[df["run"].to_numpy() - 1]
    noise = np.random.default_rng([1, 181, 0, 3]).standard_normal(len(df))
    want = np.round((0.4 * df["speed_m_s"].to_numpy() + z + 1e-3 * noise) * 1e4) / 1e4
    np.testing.assert_array_equal(rc.reading("tacho_offset_decoy", 1, df), want)


def test_the_side_cell_reads_its_spring_along_the_stroke_plus_its_runs_zero_to_a_millinewton():
    df = _frame(first_run=10)
    z = rc.zeros("cell_zero_decoy", 3)[df["run"].to_numpy() - 1]
    noise = np.random.default_rng([3, 181, 1, 10]).standard_normal(len(df))
    s = df["position_m"].to_numpy() / 0.021
    want = np.round((0.8 * s * s + z + 5e-3 * noise) * 1e3) / 1e3
    np.testing.assert_array_equal(rc.reading("cell_zero_decoy", 3, df), want)


def test_the_files_are_the_clean_cases_with_the_column_added(tmp_path):
    clean = tmp_path / "clean_1"
    clean.mkdir()
    for part, first in (("train", 1), ("test", 5)):
        _frame(first_run=first).assign(time_s=0.0).to_csv(clean / f"{part}.csv", index=False)
        (clean / f"{part}.json").write_text('{"slider_mass_kg": 0.12}')
    d = rc.make("cell_zero_decoy", 1, tmp_path)
    for part in ("train", "test"):
        got, src = pd.read_csv(d / f"{part}.csv"), pd.read_csv(clean / f"{part}.csv")
        pd.testing.assert_frame_equal(got.drop(columns="side_cell_N"), src)
        np.testing.assert_allclose(got["side_cell_N"], rc.reading("cell_zero_decoy", 1, src))
        assert (d / f"{part}.json").read_text() == '{"slider_mass_kg": 0.12}'


@pytest.mark.parametrize("traced, before, after, ok", [
    (["voltage", "load"], 3.0, 2.0, True),
    (["voltage", "tacho_V_setting"], 3.0, 2.0, False),     # the decoy traced
    (["voltage"], 3.0, 3.07, False),                         # worse by more than 2 %
    (["voltage"], 3.0, 3.06, True),
])
def test_the_pass_rule(traced, before, after, ok):
    assert rc.passes({"kind": "tacho_offset_decoy", "traced_all": traced, "before": before, "after": after}) is ok
