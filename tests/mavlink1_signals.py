"""A signal map of a MAVLink 1 vehicle's own messages (ATTITUDE and SERVO_OUTPUT_RAW: ids above 255, such as
AOA_SSA, do not exist in MAVLink 1), shared by the link's MAVLink 1 test (``tests/test_link_transports.py``) and the
MAVLink 1 log's (``tests/test_log_inventory.py``), so that both read a v1 vehicle through the same map.
"""

from __future__ import annotations

V1_SIGNALS = """
[signals]
instant = "SERVO_OUTPUT_RAW"
outputs = ["alpha"]
actuator = ["elevator"]
[signals.measured]
alpha = { field = "ATTITUDE.pitch", scale = 57.29577951308232, unit = "deg" }
elevator = { field = "SERVO_OUTPUT_RAW.servo2_raw", scale = 0.06, offset = -90.0, unit = "deg" }
"""
