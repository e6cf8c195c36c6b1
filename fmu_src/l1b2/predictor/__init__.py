"""The paper's reduced speed predictor (Eq. 25-31): model, run-level simulation, derivation.

:mod:`~l1b2.predictor.model` (parameters and the Eq. 29 step),
:mod:`~l1b2.predictor.simulate` (free runs over many runs, synthetic data),
:mod:`~l1b2.predictor.setup` (what a deployed predictor carries),
:mod:`~l1b2.predictor.derive` (parameters derived from the physical model) and
:mod:`~l1b2.predictor.effects` (the effect families of the extended predictor, one registry).
"""
