"""``kvp gateway``: many KRCs polled over KUKAVARPROXY, served as one OPC UA server.

The server follows the OPC UA for Robotics companion specification (OPC 40010-1): a
MotionDeviceSystem with one MotionDevice, Controller and SafetyState per robot, built from the
OPC Foundation's own NodeSets. See docs/gateway.md.

Modules: :mod:`.cell` (the cell file), :mod:`.model` (NodeSets and instantiation),
:mod:`.robotics` (the per-robot node tree), :mod:`.mapping` (KRL values to OPC UA values),
:mod:`.poller` (one polling task per robot) and :mod:`.schedule` (when it polls),
:mod:`.livenodes` (node values served lazily), :mod:`.writes` (the WriteVariable method),
:mod:`.passwords` (password hashes), :mod:`.security` (login rules, certificate) and
:mod:`.server` (the gateway itself).
"""
