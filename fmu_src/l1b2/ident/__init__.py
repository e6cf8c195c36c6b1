"""Maximum-likelihood identification of the Eq. 29 predictor from measured data (Eq. 32, 35).

Modules, in the order a fit uses them:

* :mod:`~l1b2.ident.extra` -- :class:`ExtraForces`, extra exogenous forces with their own parameters;
* :mod:`~l1b2.ident.problem` -- samples, force terms, residuals [m/s] and analytic Jacobian of a criterion;
* :mod:`~l1b2.ident.reduced` -- data-driven starts (linear and equation-error fits of the reduced functions);
* :mod:`~l1b2.ident.search` -- multi-start local search, Sobol boxes, the statistical stopping rule;
* :mod:`~l1b2.ident.noise` -- the noise model (per-run variance, start-speed term);
* :mod:`~l1b2.ident.uncertainty` -- Fisher / AR(1)-inflated covariance, identifiability directions;
* :mod:`~l1b2.ident.result` -- :class:`IdentificationResult` (report, strict JSON, plots, save);
* :mod:`~l1b2.ident.estimator` -- :class:`PredictorIdentifier`, the scikit-learn-style estimator
  (settings by :class:`~l1b2.ident.convention.EstimatorSettings`, shared with the close loop).
"""

from .estimator import RECOMMENDED_FIXED, PredictorIdentifier, clone, evaluation_mask
from .extra import ExtraForces
from .result import IdentificationResult, Parameter

__all__ = [
    "PredictorIdentifier", "clone", "ExtraForces", "IdentificationResult", "Parameter", "RECOMMENDED_FIXED",
    "evaluation_mask",
]
