"""The signal map of derived signals over MAVLink (alpha, beta and airspeed from LOCAL_POSITION_NED, ATTITUDE and
WIND_COV), shared by the derived signals' tests (``tests/test_derived_signals.py``, ``tests/e2e/test_derived_live.py``).
"""

from __future__ import annotations

MAVLINK_MAP = """
[signals]
instant = "ACTUATOR_OUTPUT_STATUS"
outputs = ["alpha"]
actuator = ["elevator"]
[signals.measured]
q = { derive = "degrees", input = "ATTITUDE.pitchspeed" }
elevator = { derive = "control", input = "ACTUATOR_OUTPUT_STATUS.actuator[1]", throw = [-28.0, 23.0], unit = "deg" }
[signals.measured.alpha]
derive = "angle_of_attack"
unit = "deg"
range = [-30.0, 30.0]
velocity_ned = ["LOCAL_POSITION_NED.vx", "LOCAL_POSITION_NED.vy", "LOCAL_POSITION_NED.vz"]
attitude_euler = ["ATTITUDE.roll", "ATTITUDE.pitch", "ATTITUDE.yaw"]
wind_ned = ["WIND_COV.wind_x", "WIND_COV.wind_y", "WIND_COV.wind_z"]
[signals.measured.beta]
derive = "sideslip"
velocity_ned = ["LOCAL_POSITION_NED.vx", "LOCAL_POSITION_NED.vy", "LOCAL_POSITION_NED.vz"]
attitude_euler = ["ATTITUDE.roll", "ATTITUDE.pitch", "ATTITUDE.yaw"]
wind_ned = ["WIND_COV.wind_x", "WIND_COV.wind_y", "WIND_COV.wind_z"]
[signals.measured.tas]
derive = "airspeed"
velocity_ned = ["LOCAL_POSITION_NED.vx", "LOCAL_POSITION_NED.vy", "LOCAL_POSITION_NED.vz"]
wind_ned = ["WIND_COV.wind_x", "WIND_COV.wind_y", "WIND_COV.wind_z"]
"""
