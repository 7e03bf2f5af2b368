"""``kvp web``: a phone-friendly jog pad with a live 3D view of the robot (docs/web.md).

Modules: :mod:`.command` (the typer command), :mod:`.runner` (socket, uvicorn and the tasks),
:mod:`.server` (Starlette routes, WebSocket sessions, security), :mod:`.robotlink` (the live
view's KVP polling), :mod:`.jog` (hold-to-move control) and :mod:`.jogplan` (the arithmetic
of one jog increment). The page is ``static/``; the KRL jog program is ``krl/``. This package
imports nothing at import time, so registering the command keeps ``kvp`` fast.
"""
