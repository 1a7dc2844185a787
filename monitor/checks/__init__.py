"""The checks on gains: verify, losses, margin, threshold, metrics (the norms they share with the designs live
in ``monitor.model.norms``).

Independent of the designs they judge: nothing here trusts what a design claims without recomputing it.
"""

# --alarm-threshold auto: raise at 1.25 x the proven no-fault bound on |f_hat| (run, threshold and detectability agree;
# here, not in threshold.py, so that the CLI's help text does not import numpy and scipy)
AUTO_MARGIN = 1.25

# detectability's defaults (here for the same reason): a false-alarm budget of one per flight hour, which a Monte
# Carlo of an hour can check; detection within 2 s; the Gaussian bias detected with probability 0.95
FALSE_ALARMS_PER_HOUR = 1.0
WITHIN_S = 2.0
PROBABILITY = 0.95
