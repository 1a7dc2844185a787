"""What crosses process boundaries: MAVLink framing and units, Zenoh configuration and key names.

Shared by ``monitor`` and ``sim_vehicle`` so that both sides of the wire are one definition.
"""

# The turbulence levels sim-vehicle flies (JSBSim's MIL-F-8785C model, ``atmosphere/turb-type`` = 3), each with
# its intensity as JSBSim's own table (FGWinds.h) gives it: (windspeed at 20 ft AGL in ft/s, probability-of-
# exceedance curve), None for no turbulence. sim-vehicle sets JSBSim from it, detectability scales a plant's
# [disturbance] between levels with it. Here, in the package module, so that a command's --help gets the choices
# without importing numpy.
TURBULENCE_INTENSITY: dict[str, tuple[float, int] | None] = {
    "none": None,
    "light": (25.0, 3),
    "moderate": (50.0, 4),
    "severe": (75.0, 6),
}
# the levels, as every command and plant file names them
TURBULENCE_LEVELS = tuple(TURBULENCE_INTENSITY)  # ("none", "light", "moderate", "severe")
