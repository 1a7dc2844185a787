"""sim-vehicle: the simulated UAV that the fault monitor is tested against (see README.md here)."""
