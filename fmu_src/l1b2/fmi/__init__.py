"""FMI 2.0 export: slave adapter, FMU build from one slave template, host runtime, archives.

:mod:`~l1b2.fmi.adapter` (a pythonfmu slave over a co-simulation block),
:mod:`~l1b2.fmi.build` (FMUs with complete modelDescription.xml),
:mod:`~l1b2.fmi.cache` (FMUs built on demand into a per-user cache),
:mod:`~l1b2.fmi.runtime` (what a host process needs), :mod:`~l1b2.fmi.export`
(FMUs, SSP archive and manifest) and ``chost/`` (a generic FMI 2.0 host in C).
"""
