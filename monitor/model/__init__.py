"""The model core: plant, exact discretisation with delay, delay polytope, real closed loop, loss model, estimator.

Pure functions of matrices and data (no sockets, files or clocks), so the live loop, the designs, the checks
and the tests all call the same code.
"""
