"""Heave compensation on a simulated wave platform: thesis §4.2.3 end to end (docs/heave.md).

Modules: :mod:`.geometry` (platform kinematics, eq. 4.6–4.11), :mod:`.waves` (eq. 4.13),
:mod:`.plc` / :mod:`.simulator` / :mod:`.registers` (the platform's PLC on Modbus TCP),
:mod:`.accel` (the accelerometer board and its serial stream), :mod:`.master` (the Modbus
master), :mod:`.control` and :mod:`.estimation` (the control server, eq. 4.14–4.15),
:mod:`.operator` (gamepad, keyboard, scripted), :mod:`.experiment` / :mod:`.runner` /
:mod:`.plots` / :mod:`.sweep` (the experiment and its results), :mod:`.cli` (``kvp heave``,
``kvp platform``). Nothing here is imported by ``kvp read``: the CLI imports lazily.
"""
