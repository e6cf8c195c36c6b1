"""One reading of an identification's ``fixed`` setting (:func:`l1b2.ident.pins.pinned_parameters`)."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest
from l1b2.errors import IdentificationError
from l1b2.ident.estimator import PredictorIdentifier
from l1b2.ident.extra import ExtraForces
from l1b2.ident.offset import auto_solver
from l1b2.ident.pins import pinned_parameters
from l1b2.ident.problem import ParameterSpace

#: the parameters that carry the drive offset and its gauge, written out
OFFSET = {"c_r", "sigma", "mu", "k0", "alpha_0"}


@pytest.mark.parametrize("fixed, expected", [
    (None, {}),
    ("recommended", {"sigma": None, "k0": None, "mu": None, "mu_sd": None}),
    (("mu_sd",), {"mu_sd": None}),
    (["alpha_0", "c_r"], {"alpha_0": None, "c_r": None}),
    ({"c_r": 1, "mu_sd": None}, {"c_r": 1.0, "mu_sd": None}),
    ({"mu_sd": "0.25"}, {"mu_sd": 0.25}),                   # a value is taken as a float
    ({}, {}),
    ((), {}),
])
def test_the_space_and_the_default_search_read_every_form_of_fixed_alike(fixed, expected):
    # reference: the pins written out per form; the default search is the offset search exactly when no pin
    # touches OFFSET (the cold Eq. 29 fit), the space pins exactly those names, in the order given
    got = pinned_parameters(fixed)
    assert got == expected and list(got) == list(expected) and all(
        v is None or type(v) is float for v in got.values())
    space = ParameterSpace(3, None, fixed)
    assert space.fixed == expected and list(space.fixed) == list(expected)
    assert [n for n, v in zip(space.names, space.varied) if not v] == [n for n in space.names if n in expected]
    cfg = PredictorIdentifier(order=3, fixed=fixed)._checked_settings()
    assert cfg.solver == ("joint" if set(expected) & OFFSET else "offset_kappa0")
    assert auto_solver(cfg) == cfg.solver


def test_the_pins_of_extra_forces_are_known_to_the_space():
    extra = ExtraForces(("const_N",), ("N",), lambda df: None)
    space = ParameterSpace(3, extra, {"const_N": 0.5})
    assert space.fixed == {"const_N": 0.5} and space.fixed_values == {"const_N": 0.5}
    assert not space.varied[space.names.index("const_N")] and space.varied.sum() == space.size - 1


@pytest.mark.parametrize("fixed, message", [
    ("recommend", "fixed: unknown preset 'recommend' (use 'recommended' or a dict)"),
    (3, "fixed: expected None, 'recommended', a sequence of names or a mapping, got 3"),
    ({"mu_sd": "a lot"}, "fixed: the value of 'mu_sd' is not a number: 'a lot'"),
    ({"mu_sd": [0.1, 0.2]}, "fixed: the value of 'mu_sd' is not a number: [0.1, 0.2]"),
])
def test_a_bad_fixed_is_refused_alike_by_the_space_and_the_default_search(fixed, message):
    # reference: the same error, with the same text, whichever reads it first
    for read in (lambda: pinned_parameters(fixed), lambda: ParameterSpace(3, None, fixed),
                 lambda: PredictorIdentifier(order=3, fixed=fixed)._checked_settings()):
        with pytest.raises(IdentificationError) as err:
            read()
        assert str(err.value) == message


def test_an_unknown_name_is_refused_where_the_names_are_known():
    # the default search reads the pins before the space knows the parameters: the space refuses the name
    with pytest.raises(IdentificationError, match=r"fixed: unknown parameter 'gamma'; known: \['c_r', "):
        ParameterSpace(3, None, {"gamma": 1.0})
    with pytest.raises(IdentificationError, match="fixed: unknown parameter 'gamma'"):
        pinned_parameters(["gamma"], names=["c_r", "sigma"])
    assert pinned_parameters(["gamma"]) == {"gamma": None}
    assert PredictorIdentifier(order=3, fixed=["gamma"])._checked_settings().solver == "offset_kappa0"
