"""The checks on gains: verify, losses, margin, threshold, metrics, and the norms they share.

Independent of the designs they judge: nothing here trusts what a design claims without recomputing it.
"""
