"""The scaled likelihood objective of a data frame, shared by the tests of the search's building blocks."""

import numpy as np
from l1b2.ident.estimator import evaluation_mask
from l1b2.ident.noise import NoiseModel
from l1b2.ident.problem import LikelihoodProblem, SampleData, ScaledObjective, param_scale
from l1b2.predictor.model import PredictorParams

def scaled_objective(df, theta, m_s, order=3, *, varied=None, start_noise=True, criterion="free_run"):
    """The ``ScaledObjective`` of ``df`` at ``theta`` for slider mass ``m_s`` [kg] (common noise variance, noise model updated at ``theta``).

    ``varied``: the mask of varied parameters (default all); ``start_noise``: whether the start gains are fitted.
    """
    data = SampleData(df, evaluation_mask(df))
    prob = LikelihoodProblem(data, order, 0.5, True, criterion, 0.0, 0.02, m_s)
    lo, hi = PredictorParams.bounds(order)
    noise = NoiseModel(prob.run_sel, data.layout.R, "common")
    varied = np.ones(theta.size, bool) if varied is None else varied
    obj = ScaledObjective(prob, noise, theta, varied, param_scale(theta, order), lo, hi, start_noise)
    obj.update_noise(theta)
    return obj


def central_difference(f, x, j, floor):
    """``(f(x + h e_j) - f(x - h e_j)) / 2h`` with ``h = 1e-6 max(|x_j|, floor)``: the finite-difference reference of a sensitivity."""
    step = 1e-6 * max(abs(x[j]), floor)
    xp, xm = x.copy(), x.copy()
    xp[j] += step
    xm[j] -= step
    return (f(xp) - f(xm)) / (2 * step)
