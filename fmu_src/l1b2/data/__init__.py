"""Measured data: the data contract (:mod:`~l1b2.data.measurements`), error metrics and plots."""
