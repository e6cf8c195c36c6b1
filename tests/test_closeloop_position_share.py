"""The channels' position share: how much of a logged channel is a function of the position in the baseline's own
position series (``diagnosis.channels_considered[*].position_share``)."""

import numpy as np
import pandas as pd
from numpy.polynomial import polynomial as P
from numpy.polynomial.legendre import legvander

from l1b2.closeloop.evidence import channels_considered, position_share, with_position_share
from l1b2.closeloop.selection import position_basis


def _r2_written_out(x, c, degree):
    """R^2 of ``c`` on the polynomials of ``x`` up to ``degree`` (the span of the Legendre series of that order),
    fitted by numpy's power-series least squares: an independent computation."""
    fit = P.polyval(x, P.polyfit(x, c, degree))
    return 1.0 - np.sum((c - fit) ** 2) / np.sum((c - np.mean(c)) ** 2)


def test_position_share_is_the_r2_of_the_channel_on_the_position_series():
    rng = np.random.default_rng(3)
    x = rng.uniform(-1, 1, 400)
    c = 48500.0 + 600.0 * np.tanh(2 * x) + 40.0 * rng.standard_normal(400)   # a channel mostly set by the position
    share = position_share(c, legvander(x, 5))
    assert abs(share - _r2_written_out(x, c, 5)) < 1e-9
    assert 0.9 < share < 1.0


def test_position_share_is_one_for_a_function_of_the_position_and_zero_for_a_run_level_sign():
    x = np.tile(np.linspace(-1, 1, 50), 4)                      # four runs over the same positions
    assert abs(position_share(3.0 + x - 0.5 * x ** 3, legvander(x, 8)) - 1.0) < 1e-12
    sign = np.repeat([1.0, -1.0, 1.0, -1.0], 50)                # a run-level value, balanced at every position
    assert abs(position_share(sign, legvander(x, 8))) < 1e-12
    assert np.isnan(position_share(np.full(200, 2.0), legvander(x, 8)))


class _Params:
    """What :func:`position_basis` reads of a predictor's parameters: its scaled position and its order."""

    order = 3
    s_center, s_half = 0.0, 0.02

    def scaled_position(self, s):
        return (np.asarray(s, float) - self.s_center) / self.s_half


def test_the_records_carry_the_share_on_the_masked_samples_and_none_without_a_hypothesis():
    rng = np.random.default_rng(0)
    s = np.tile(np.linspace(-0.02, 0.025, 60), 2)   # beyond the scaled range: clipped at 1.2 as the nuisance is
    f = 48500.0 + 3e4 * s + 5.0 * rng.standard_normal(120)
    df = pd.DataFrame({"position_m": s, "frequency_Hz": f, "aux": np.ones(120), "tip": f})
    mask = np.arange(120) % 7 != 0
    chans = ({"name": "frequency_Hz", "kind": "logged", "sd": 1.0, "within_run": True},
             {"name": "aux", "kind": "logged", "sd": 0.0, "within_run": False},
             {"name": "tip", "kind": "response", "sd": 1.0, "within_run": True})
    out = {c["name"]: c for c in with_position_share(chans, df, mask, _Params())}
    x = np.clip(s[mask] / 0.02, -1.2, 1.2)
    assert np.allclose(position_basis(_Params(), s[mask]), legvander(x, 3))
    assert abs(out["frequency_Hz"]["position_share"] - _r2_written_out(x, f[mask], 3)) < 1e-9
    assert out["aux"]["position_share"] is None and out["tip"]["position_share"] is None
    rows = {r["channel"]: r for r in channels_considered(tuple(out.values()), [], 1e-3, 0.05, set())}
    assert rows["frequency_Hz"]["position_share"] == out["frequency_Hz"]["position_share"]
    assert rows["voltage_V"]["position_share"] is None   # an input's row: run-level evidence only
