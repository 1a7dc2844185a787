"""The verifier's own parts, on systems whose answers are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.checks.verify import _growth_rate, verify_gains
from monitor.design.paper import lemma3_K2_K3
from monitor.model.closed_loop import Gains
from monitor.model.norms import hinf_norm
from monitor.model.plant import load_plant


def test_hinf_norm_of_a_first_order_lag_peaks_at_dc():
    a = 0.8
    assert hinf_norm(np.array([[a]]), np.array([[1.0]]), np.array([[1.0]])) == pytest.approx(1 / (1 - a), rel=1e-9)


def test_hinf_norm_finds_a_sharp_resonance():
    r, w0 = 0.995, 1.3
    A = r * np.array([[np.cos(w0), -np.sin(w0)], [np.sin(w0), np.cos(w0)]])
    B, C = np.array([[1.0], [0.0]]), np.array([[1.0, 0.0]])
    grid = np.linspace(0, np.pi, 200001)
    exact = max(
        abs((C @ np.linalg.solve(np.exp(1j * w) * np.eye(2) - A, B)).item())
        for w in grid[(grid > 1.25) & (grid < 1.35)]
    )
    assert hinf_norm(A, B, C) == pytest.approx(exact, rel=1e-5)


def test_hinf_norm_of_an_unstable_system_is_infinite():
    assert np.isinf(hinf_norm(np.array([[1.1]]), np.array([[1.0]]), np.array([[1.0]])))


def test_growth_rate_detects_switching_instability_of_stable_matrices():
    A1 = np.array([[0.0, 2.0], [0.0, 0.0]]) + 0.5 * np.eye(2) * 0  # nilpotent: spectral radius 0
    A2 = A1.T
    assert max(abs(np.linalg.eigvals(A1))) < 1 and max(abs(np.linalg.eigvals(A2))) < 1
    assert _growth_rate([A1, A2], np.random.default_rng(0)) > 1.5  # alternating products grow like 2^k


def test_published_gains_are_unstable_on_the_real_loop():
    for preset in ("paper", "paper-continuous"):
        p = load_plant(preset)
        K2, K3 = lemma3_K2_K3(p)
        g = Gains(L=np.array([[0.0124], [-0.0008]]), M=np.array([[0.8486]]), K1=np.array([[-11.2657]]), K2=K2, K3=K3)
        v = verify_gains(p, g)
        assert not v.stable and v.rho_max > 3.0 and np.isinf(v.hinf_ef)
