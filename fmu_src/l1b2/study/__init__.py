"""Multi-seed studies of the identification and of the close-the-loop job on the virtual rig.

Each study repeats one check over many seeds of a rig world (run order, noise,
run-to-run scatter and the injected effect's size all drawn from the seed),
fans the seeds out through the parallel engine (:mod:`l1b2.cluster`) and
collects one row per seed in a :class:`~l1b2.study.result.StudyResult`:

* ``coverage`` (:mod:`~l1b2.study.recovery`): for every injection whose
  effect family has a physical parameter, the model *with* that family is
  identified and its 95 % intervals are checked against the injected value;
* ``control`` (:mod:`~l1b2.study.control`): the close-the-loop job on data
  without any injected effect; its held-out error against the baseline's.

Files are written by :func:`l1b2.workflows.run_study` only.
"""
