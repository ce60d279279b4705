"""The linearisation's driving-force term (valve_dolfinx.contact.linearisation) against its
formula written out per row.

The whole contact Jacobian, these terms included, is checked against finite differences
with the contact models (test_contact_model.py)."""

from __future__ import annotations

import numpy as np

from valve_dolfinx.contact.linearisation import turning_load


def test_turning_load_is_minus_the_slope_times_the_transposed_direction_derivative():
    rng = np.random.default_rng(4)
    dn, load, slope = rng.normal(size=(20, 4, 3, 3)), rng.normal(size=(20, 3)), rng.normal(size=20)
    expected = np.array([[-slope[a] * dn[a, m].T @ load[a] for m in range(4)]
                         for a in range(20)])
    assert np.allclose(turning_load(dn, load, slope), expected, rtol=1e-14, atol=1e-14)
