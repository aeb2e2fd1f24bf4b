"""Fit a rider: a preset's numbers from horse takes and the rider recorded with them (``riderlive fit``).

Pure core: :mod:`~riderlive.fit.vector` (the parameter vector and its bounds),
:mod:`~riderlive.fit.dual` (the rules' derivatives from their one source),
:mod:`~riderlive.fit.problem` (the objective), :mod:`~riderlive.fit.identify`
(identifiability and uncertainty), :mod:`~riderlive.fit.offset` (the clock offset) and
:mod:`~riderlive.fit.solve` (Levenberg-Marquardt). I/O at the edges: the take readers,
the preset writer, the report and the command (``docs/fit.md``).
"""
