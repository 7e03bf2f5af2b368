"""The physical robot behind the emulated controller: what the drives make of the set-points.

The motion kernel produces IPO set-points (joint positions every 12 ms). A *plant* turns them
into what a KRC4 measures and publishes:

* ``ideal`` — no plant object: the measured axes are the set-point and ``$TORQUE_AXIS_ACT`` is
  the kinematics package's statics (exact values, for tests).
* ``dynamic`` — :class:`~.dynamic.DynamicPlant`: a MuJoCo rigid-body model of the KR 6 R900
  sixx, or of the arm ``--robot`` names (its own model file, :mod:`kukavarproxy_emu.robots`)
  (inertia, friction, motor inertia, payload) driven by joint servos, with sensor noise,
  external wrenches and contact with :class:`Obstacle` objects, optionally with a calibration
  error (the physical robot differs from the nominal model).

The plant's own parameters and their sources are in ``kr6r900sixx_dynamics.toml`` (not the
client library's kinematic model: the plant is the world the apps estimate); see
docs/emulator-robot.md. MuJoCo is imported only when a dynamic plant is built.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

from pyopenshowvar.extras import require

from .contact import Obstacle

if TYPE_CHECKING:  # the config imports this package: keep it light
    import numpy as np
    import numpy.typing as npt

    from pyopenshowvar.kinematics import RobotModel

    from ..store import VariableStore
    from .dynamic import DynamicPlant, Truth
    from .params import PlantParams

__all__ = ["PLANTS", "Obstacle", "Plant", "make_plant"]

#: ``--plant`` choices.
PLANTS = ("ideal", "dynamic")


class Plant(Protocol):
    """What the motion kernel needs of a plant: one call per IPO cycle; and what the robot
    needs when an axis cannot follow (``on_fault``, the brakes, :meth:`release`)."""

    kind: str
    truth: Truth
    resting: bool
    braked: bool
    on_fault: Callable[[str], None] | None

    @property
    def position(self) -> npt.NDArray[np.float64]: ...

    def step(self, q_set_deg: npt.NDArray[np.float64]) -> None: ...

    def release(self) -> npt.NDArray[np.float64]: ...


def make_plant(
    kind: str,
    store: VariableStore,
    model: RobotModel,
    *,
    ipo: float = 0.012,
    calibration_seed: int | None = None,
    encoder_noise: float | None = None,
    torque_noise: float | None = None,
    seed: int | None = None,
    obstacles: Sequence[Obstacle] = (),
    params: PlantParams | None = None,
) -> DynamicPlant | None:
    """The plant ``kind`` (None for ``ideal``); raises ``ValueError`` for an unknown kind."""
    if kind == "ideal":
        if calibration_seed is not None or obstacles:
            raise ValueError("calibration error and obstacles need the dynamic plant")
        return None
    if kind != "dynamic":
        raise ValueError(f"unknown plant {kind!r} (known: {', '.join(PLANTS)})")
    # MuJoCo only when needed, and a missing MuJoCo names the extra that brings it
    dynamic = require(
        "kukavarproxy_emu.plant.dynamic",
        "the dynamic plant (the default; --plant ideal needs nothing more)",
    )
    plant: DynamicPlant = dynamic.DynamicPlant(
        store,
        model,
        ipo=ipo,
        calibration_seed=calibration_seed,
        encoder_noise=encoder_noise,
        torque_noise=torque_noise,
        seed=seed,
        obstacles=obstacles,
        params=params,
    )
    return plant
