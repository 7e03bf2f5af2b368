"""`Load.from_krl`: the controller's $LOAD text as a payload for the gravity model."""

from __future__ import annotations

import numpy as np

from pyopenshowvar.kinematics import KR6R900SIXX, Load, gravity_torques
from pyopenshowvar.krl import parse_value

HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])


def test_load_from_captured_krl_text() -> None:
    text = (
        "{LOAD: M 6.00000, CM {FRAME: X 0.0, Y 0.0, Z 50.0000, A 0.0, B 0.0, C 0.0}, "
        "J {INERTIA: X 0.0, Y 0.0, Z 0.0}}"
    )
    load = Load.from_krl(parse_value(text))
    assert load == Load(6.0, (0.0, 0.0, 50.0))
    # reference §3.3: 6 kg 50 mm along the flange at HOME
    np.testing.assert_allclose(
        gravity_torques(KR6R900SIXX, HOME, load), [0, -57.2, -57.9, -0.8, -8.3, 0], atol=0.1
    )


def test_no_mass_or_no_struct_is_no_load() -> None:
    assert Load.from_krl(parse_value("{LOAD: M 0.0}")) is None
    assert Load.from_krl(parse_value("{LOAD: M -1.0}")) is None  # KUKA's "no load" default
    assert Load.from_krl(12.5) is None
    assert Load.from_krl(parse_value("{LOAD: M 2.5}")) == Load(2.5)  # missing CM counts as 0
