"""The suite-wide guard (tests/conftest.py) turns unhandled asyncio errors into failures."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

LEAKY = """
import asyncio
import gc


async def test_unretrieved_future():
    fut = asyncio.get_running_loop().create_future()
    fut.set_exception(RuntimeError("nobody looks at me"))
    del fut


def test_exception_in_callback():
    loop = asyncio.new_event_loop()
    loop.call_soon(lambda: 1 / 0)
    loop.run_until_complete(asyncio.sleep(0.01))
    loop.close()


async def test_unretrieved_task_exception():
    async def boom():
        raise ValueError("lost")

    asyncio.get_running_loop().create_task(boom())
    await asyncio.sleep(0.01)


async def test_clean():
    await asyncio.sleep(0)


async def test_expected_errors_can_be_cleared(asyncio_errors):
    fut = asyncio.get_running_loop().create_future()
    fut.set_exception(RuntimeError("on purpose"))
    del fut
    gc.collect()
    assert any("never retrieved" in r.getMessage() for r in asyncio_errors)
    asyncio_errors.clear()
"""


def test_unhandled_asyncio_errors_fail_the_test_that_logged_them(
    pytester: pytest.Pytester, asyncio_errors: list[logging.LogRecord]
) -> None:
    pytester.makeconftest((Path(__file__).parent / "conftest.py").read_text())
    pytester.makepyfile(test_leaky=LEAKY)
    result = pytester.runpytest_inprocess(
        "-p", "no:cacheprovider", "-o", "asyncio_mode=auto",
        "-o", "asyncio_default_fixture_loop_scope=function",
    )  # fmt: skip
    asyncio_errors.clear()  # the inner run's errors reach this run's guard too: expected
    result.assert_outcomes(passed=5, errors=3)
    out = result.stdout.str()
    assert "Future exception was never retrieved" in out
    assert "Exception in callback" in out
    assert "Task exception was never retrieved" in out
