"""What crosses process boundaries: MAVLink framing and units, Zenoh configuration and key names.

Shared by ``monitor`` and ``sim_vehicle`` so that both sides of the wire are one definition.
"""

# the turbulence levels sim-vehicle flies (JSBSim's MIL-F-8785C model), as every command and plant file names them:
# here, in the package module, so that a command's --help gets the choices without importing numpy
TURBULENCE_LEVELS = ("none", "light", "moderate", "severe")
