"""The live service: the per-vehicle loop, its recording and its publishers."""
