"""A TEST recorded on a clock of its own (l1b2.closeloop.othersession): which added effects predict TRAIN's
session average on it, the report's record and line. Fast unit tests; the loop's end-to-end case (TEST's free
run at the session average equals the calibrated model's) is in tests/test_closeloop_session_blocks.py.
"""

from l1b2.closeloop import othersession as osn
from l1b2.closeloop.acceptance import EffectSet
from l1b2.closeloop.candidates import CandidateForce
from l1b2.closeloop.report import loop_check_lines, other_session_line
from l1b2.predictor.effects import blocks as fb


def _effects():
    blocks = CandidateForce("session_blocks(3)", "session_block", "run", ("block_0_run_gain", "block_1_run_gain"),
                            ("N", "N"), None, generic=True,
                            spec={"kind": "session_blocks", **fb.blocks_spec((10.0, 20.0), (0.3, 0.4))})
    chan = CandidateForce("channel_x", "x", "run", ("x_gain",), ("N",), None, generic=True,
                          spec={"kind": "channel", "channel": "x", "level": "run", "form": "force_factor"})
    return EffectSet().add(chan, [0.1]).add(blocks, [0.2, -0.1]), blocks.label


def _clock():
    """A drift of the session clock, ``channel_time_s[force_factor, run]``: it reads ``run:time_s``."""
    return CandidateForce("channel_time_s", "time", "force_factor, run", ("time_s_gain",), ("N",), None,
                          generic=True,
                          spec={"kind": "channel", "channel": "time_s", "level": "run", "form": "force_factor"})


def test_only_the_facts_of_the_session_are_held_at_its_average_and_only_on_another_sessions_test():
    effects, label = _effects()
    assert osn.session_facts(effects) == [label]
    assert osn.session_facts(EffectSet()) == []
    assert osn.record(True, effects) == {"one_session": True, "session_average": [], "own_clock": []}
    assert osn.record(False, effects) == {"one_session": False, "session_average": [label], "own_clock": []}
    # the session clock's drift is no fact of the session: it reads TEST's own times, and the record names it;
    # the blocks read the clock too, but only to place a run in its block
    drift = effects.add(_clock(), [0.3])
    assert osn.clock_readers(drift) == [_clock().label] and osn.session_facts(drift) == [label]
    assert osn.record(False, drift)["own_clock"] == [_clock().label]
    assert osn.record(True, drift)["own_clock"] == []
    # a user's candidate with a feature function and no spec is neither (no family to ask)
    own = CandidateForce("my_term", "x", "", ("k",), ("N",), lambda df: df["x"].to_numpy(), generic=True)
    assert osn.record(False, drift.add(own, [0.0])) == {"one_session": False, "session_average": [label],
                                                        "own_clock": [_clock().label]}
    assert osn.for_test("model", effects, True) == "model"            # one session: the model as fitted
    assert osn.averaged("model", EffectSet()) == "model"                 # nothing to hold: the model as fitted


def test_the_report_names_the_effects_held_at_the_session_average_on_another_sessions_test():
    effects, label = _effects()
    assert other_session_line(None) == "" and other_session_line(osn.record(True, effects)) == ""
    assert other_session_line({"one_session": False, "session_average": []}) == ""
    line = other_session_line(osn.record(False, effects))
    assert line == ("TEST's runs overlap TRAIN's in time (TEST was recorded on a clock of its own): TEST is predicted "
                    f"at TRAIN's session average of `{label}`, not at the level of the block its times fall in")
    assert loop_check_lines({"test_session": osn.record(False, effects)}, {}) == [line]
    clock = _clock().label
    both = other_session_line(osn.record(False, effects.add(_clock(), [0.3])))
    assert both == line + (f"; `{clock}` read TEST's own times as TRAIN's session clock (right for a course since "
                           "the session's start, not for one over the rig's life)")
    only = other_session_line(osn.record(False, EffectSet().add(_clock(), [0.3])))
    assert only == (f"TEST's runs overlap TRAIN's in time (TEST was recorded on a clock of its own): `{clock}` "
                    "read TEST's own times as TRAIN's session clock (right for a course since the session's start, "
                    "not for one over the rig's life)")
