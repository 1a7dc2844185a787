"""A test-side ``Sink`` for the vehicle's event simulation, shared by the sim_vehicle test modules
(``test_sim_simulation``, ``test_sim_flight_models``, ``test_sim_jsbsim``): it keeps what the vehicle sent
(samples, truth payloads, a count of heartbeats) so that a test drives ``Simulation`` without sockets.
"""

from __future__ import annotations


class Recorder:
    """The simulation's Sink, keeping what the vehicle sent (shared by the sim_vehicle test modules)."""

    def __init__(self) -> None:
        self.samples, self.truth, self.heartbeats = [], [], 0

    def send_sample(self, sample) -> None:
        self.samples.append(sample)

    def send_heartbeat(self) -> None:
        self.heartbeats += 1

    def publish_truth(self, payload) -> None:
        self.truth.append(payload)
