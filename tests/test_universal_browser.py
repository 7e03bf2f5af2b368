"""``kvp universal``'s page in headless Chromium: the pad's 3D view draws any arm, a held button
moves it, letting go stops it; takes a screenshot (docs/universal.png with
KVP_SAVE_SCREENSHOTS=1). Skipped (with the
reason as a warning) where no browser can be installed, like the web pad's browser test,
whose Chromium fixture this reuses."""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path
from typing import Any

import numpy as np
from pyopenshowvar_apps.universal.server import ControlServer
from pyopenshowvar_apps.universal.sim import SimulatedArm
from pyopenshowvar_apps.universal.web import ViewServer, WebInput
from test_web_browser import _wait_js, browser, screenshot_path  # noqa: F401 - the Chromium fixture

from kukavarproxy_emu.testing import wait_until
from pyopenshowvar.arms import load_arm


async def test_universal_page_in_chromium(browser: Any, tmp_path: Path) -> None:  # noqa: F811
    web_input = WebInput()
    backend = SimulatedArm(load_arm("knuckle_boom_crane"))
    server = ControlServer(backend, web_input, solver="closed-form", mode="velocity",
                           arms=["knuckle_boom_crane", "adept_cobra600", "kuka_youbot_arm"])  # fmt: skip
    await server.start()
    loop = asyncio.create_task(server.run())
    try:
        async with ViewServer(server, web_input, port=0) as view:
            page = await browser.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            await page.goto(view.url)
            await _wait_js(page, "window.kvpUniversal.states > 3")
            await _wait_js(page, "!document.querySelector('.jog').disabled")
            assert await page.evaluate("document.getElementById('solver').value") == "closed-form"
            tip0 = server.ticks[-1].tip
            button = page.locator('.jog[data-key="Z"][data-dir="1"]')
            box = await button.bounding_box()
            await page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
            await page.mouse.down()
            # events, not sleeps: a loaded machine takes longer to send, tick and move
            await wait_until(lambda: server.ticks[-1].signal[2] > 0, 20, what="the held button")
            await wait_until(
                lambda: server.ticks[-1].tip[2] - tip0[2] > 100.0, 20, what="the crane's tip up"
            )
            await page.mouse.up()
            await wait_until(lambda: np.all(server.ticks[-1].signal == 0), 20, what="let go")
            assert server.ticks[-1].alive
            assert server.ticks[-1].tip[2] - tip0[2] > 100.0  # the crane's tip went up
            await page.screenshot(path=str(screenshot_path("universal.png", tmp_path)))
            assert not errors, errors
    finally:
        loop.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await loop
        await server.close()
