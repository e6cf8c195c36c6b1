"""Measured data: the data contract, error metrics and plots.

:mod:`~l1b2.data.measurements` is the public API (the ``Measurements``
container, loading, writing, splitting; it re-exports the contract's names).
Behind it: :mod:`~l1b2.data.columns` (column names, units, sidecar fields,
thresholds), :mod:`~l1b2.data.validate` (the contract's rules) and
:mod:`~l1b2.data.io` (the CSV and sidecar files). :mod:`~l1b2.data.metrics`
scores speed predictions, :mod:`~l1b2.data.plots` draws the data.
"""
