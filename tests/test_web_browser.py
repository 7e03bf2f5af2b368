"""`kvp web` in a real browser: headless Chromium (Debian's package) driven by Playwright.

The page is loaded from a web server talking KVP to an emulator that runs the shipped KVP_JOG
program. The test holds "A1 +" with the mouse and checks over KVP that A1 moved and stopped
after the release, that hiding the tab stops a jog, that the page refuses to work without the
token, and takes a screenshot (docs/web.png with KVP_SAVE_SCREENSHOTS=1). It is skipped (with the reason as a warning)
only where no browser can be installed; .ci/run installs chromium with apt-get.
"""

from __future__ import annotations

import asyncio
import importlib.util
import os
import shutil
import warnings
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from pyopenshowvar_apps.web.runner import KRL_DIR, WebServer

from kukavarproxy_emu import Emulator, EmulatorConfig
from pyopenshowvar import Client

TOKEN = "browser-token-42"
DOCS = Path(__file__).resolve().parents[1] / "docs"


def screenshot_path(name: str, tmp_path: Path) -> Path:
    """Where a browser test saves its screenshot: ``docs/NAME`` when KVP_SAVE_SCREENSHOTS=1
    (to refresh the documentation's pictures), else the test's own folder, so that a test run
    never changes a tracked file."""
    return (DOCS if os.environ.get("KVP_SAVE_SCREENSHOTS") == "1" else tmp_path) / name


#: What Chromium needs to run as root in a container, isolated from the network and profile.
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def _chromium() -> str:
    if importlib.util.find_spec("playwright") is None:
        reason = "playwright is not installed (pip install -e '.[test]')"
    else:
        found = shutil.which("chromium") or shutil.which("chromium-browser")
        if found:
            return found
        reason = "no Chromium found (apt-get install chromium chromium-driver)"
    warnings.warn(f"browser test skipped: {reason}", stacklevel=2)
    pytest.skip(reason)


@pytest.fixture
async def browser(tmp_path: Path) -> AsyncIterator[Any]:
    executable = _chromium()
    from playwright.async_api import async_playwright

    async with async_playwright() as pw:
        context = await pw.chromium.launch_persistent_context(
            str(tmp_path / "profile"),  # a new, empty profile
            executable_path=executable,
            args=CHROMIUM_ARGS,
            headless=True,
            viewport={"width": 1200, "height": 860},
        )
        try:
            yield context
        finally:
            await context.close()


async def _wait_js(page: Any, expression: str, timeout: float = 10.0) -> None:
    """Poll a JS expression with page.evaluate (wait_for_function would need 'unsafe-eval',
    which the page's Content-Security-Policy forbids)."""
    async with asyncio.timeout(timeout):
        while not await page.evaluate(expression):  # noqa: ASYNC110 - polling a browser or KVP is what a client does
            await asyncio.sleep(0.05)


async def _settled(kvp: Client) -> float:
    async with asyncio.timeout(5):
        while await kvp.read("JOG_MODE") != "0":  # noqa: ASYNC110 - polling a browser or KVP is what a client does
            await asyncio.sleep(0.02)
        a, b = 0.0, 1.0
        while abs(a - b) > 1e-3:  # still, within a dynamic plant's encoder noise
            a = float((await kvp.read_joint_angles())[0])
            await asyncio.sleep(0.1)
            b = float((await kvp.read_joint_angles())[0])
    return b


async def test_jog_pad_in_chromium(browser: Any, tmp_path: Path) -> None:
    config = EmulatorConfig(
        port=0,
        program=str(KRL_DIR / "kvp_jog.src"),
        config_files=(KRL_DIR / "kvp_jog_config.dat",),
    )
    async with (
        Emulator(config) as emu,
        WebServer("127.0.0.1", emu.port, token=TOKEN, emulated=True) as web,
        Client("127.0.0.1", emu.port) as kvp,
    ):
        # The page's own stops (button up, tab hidden) are under test here, not the server's
        # keep-alive timeout (tests/test_web_jog.py), which a stalled loop could trigger first.
        web.jog.hold_timeout = 5.0
        page = await browser.new_page()
        errors: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))

        # Without the token the page loads but its WebSocket is refused: nothing can be done.
        await page.goto(web.page_url("127.0.0.1").split("#")[0])
        await _wait_js(page, "document.getElementById('banner').textContent.includes('refused')")
        assert await page.evaluate("window.kvpStats.firstState") is None

        await page.close()
        page = await browser.new_page()
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        await page.goto(web.page_url("127.0.0.1"))
        await _wait_js(page, "window.kvpStats.firstState !== null")
        await _wait_js(page, "!document.querySelector('.jog').disabled")
        first_state_ms = await page.evaluate("window.kvpStats.firstState")

        # Hold A1 + for a moment, then let go: A1 moves, then stops.
        await page.locator('.jog[data-key="A1"][data-dir="1"]').hover()
        await page.mouse.down()
        await asyncio.sleep(0.5)
        await page.mouse.up()
        a1 = await _settled(kvp)
        assert a1 > 0.5, "A1 did not move while the button was held"
        assert web.jog.last_stop is not None and web.jog.last_stop[0] == "released"
        await asyncio.sleep(0.2)
        # still (a dynamic plant's servo may creep a hundredth of a degree into place)
        assert abs(float((await kvp.read_joint_angles())[0]) - a1) < 0.02, "A1 moved after release"

        # Hiding the tab while a button is held stops the jog too.
        await page.locator('.jog[data-key="A1"][data-dir="-1"]').hover()
        await page.mouse.down()
        await asyncio.sleep(0.3)
        await page.evaluate(
            "Object.defineProperty(document, 'visibilityState', {value: 'hidden', configurable: true});"
            "document.dispatchEvent(new Event('visibilitychange'))"
        )
        a1_hidden = await _settled(kvp)
        await page.mouse.up()
        assert a1_hidden < a1 and web.jog.last_stop[0] == "tab hidden"

        # The live view keeps updating at >= 10 Hz (the server polls at 20 Hz); the rate is
        # counted over the last 2 s, and the page has been open longer than that by now.
        rate = await page.evaluate("window.kvpStats.rate")
        assert rate >= 10.0, f"live updates at {rate:.1f} Hz"
        shown = await page.locator('.row[data-key="A1"] .val').text_content()
        assert abs(float(shown.rstrip("°")) - a1_hidden) < 0.03  # the view shows where A1 is
        await page.screenshot(path=str(screenshot_path("web.png", tmp_path)))
        assert not errors, errors
        print(f"first state {first_state_ms:.0f} ms after navigation, live rate {rate:.1f} Hz")
