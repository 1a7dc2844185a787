"""What crosses process boundaries: MAVLink framing and units, Zenoh configuration and key names.

Shared by ``monitor`` and ``sim_vehicle`` so that both sides of the wire are one definition.
"""
