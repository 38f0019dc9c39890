"""Applications built on the calibration: the paper's studies of a front (:mod:`.study`), a
fleet of rigs from a manifest (:mod:`.batch`), every camera of a rig folder (:mod:`.rig`).

Each is a library function the command line calls (``paretocal study``, ``paretocal batch``,
``paretocal calibrate RIG``): :func:`paretocal.run_study`, :func:`paretocal.run_batch`,
:func:`paretocal.calibrate_rig`.
"""
