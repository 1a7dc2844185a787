"""UAV telemetry-in-the-loop fault monitor.

The maths core (``plant``, ``discretize``, ``closed_loop``, ``design``, ``verify``) is pure: no sockets,
files or clocks, so the offline tools, the live service and the tests all run the same functions.
"""

__version__ = "0.1.0"
