"""Shared fixtures and the suite-wide guard against unhandled asyncio errors.

Fixtures: the in-process emulator (real TCP on 127.0.0.1, ephemeral port), from
``kukavarproxy_emu.testing``.

The guard: asyncio reports a failure nobody handled ("Future exception was never retrieved",
"Task exception was never retrieved", "Exception in callback ...", a task destroyed while
pending, "socket.send() raised exception") only as a log record, so a test that leaks one
still passes. Every such record emitted while a test runs — its setup, call and teardown, in
any thread — fails that test at teardown, after a ``gc.collect()`` so futures dropped by the
test are finalised (and reported) inside it rather than in a later test; records that appear
only at the final collection fail the session. A test that provokes
such errors on purpose takes the ``asyncio_errors`` fixture and clears what it expected.
"""

from __future__ import annotations

import asyncio
import gc
import logging
from collections.abc import Generator, Iterator

import pytest
import slow_first

pytest_plugins = ["kukavarproxy_emu.testing", "pytester"]

#: WARNING-level asyncio records that are unhandled failures too (asyncio logs them at WARNING).
_WARNINGS_THAT_FAIL = ("socket.send() raised exception",)


class _AsyncioErrorLog(logging.Handler):
    """Collects the asyncio logger's error records (any thread) for the running test."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.levelno >= logging.ERROR or any(
            text in record.getMessage() for text in _WARNINGS_THAT_FAIL
        ):
            self.records.append(record)

    def describe(self) -> str:
        lines = []
        for record in self.records:
            lines.append(f"{record.levelname} {record.name}: {record.getMessage()}")
            if record.exc_info and record.exc_info[1] is not None:
                exc = record.exc_info[1]
                lines.append(f"    {type(exc).__name__}: {exc}")
        return "\n".join(lines)


_guard = _AsyncioErrorLog()


def pytest_configure(config: pytest.Config) -> None:
    logging.getLogger("asyncio").addHandler(_guard)
    asyncio.BaseEventLoop.__init__ = _counting_loop_init  # type: ignore[method-assign]
    config.addinivalue_line(
        "markers", "asyncio_errors_expected: the test provokes unhandled asyncio errors on purpose"
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # the longest tests first: see slow_first.py
    slow_first.order(items, slow_first.load())


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    gc.unfreeze()
    gc.collect()
    if _guard.records:  # dropped by a test but finalised only now
        print("\nunhandled asyncio errors were logged after the tests:\n" + _guard.describe())
        _guard.records.clear()
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_unconfigure(config: pytest.Config) -> None:
    logging.getLogger("asyncio").removeHandler(_guard)
    asyncio.BaseEventLoop.__init__ = _base_loop_init  # type: ignore[method-assign]


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> Generator[None, None, None]:
    # A record left over from before this test (collection, a previous test's stray thread)
    # is not this test's fault; it was reported where it happened if it happened in a test.
    _guard.records.clear()
    return (yield)


_loops_created = 0
_base_loop_init = asyncio.BaseEventLoop.__init__


def _counting_loop_init(self: asyncio.BaseEventLoop) -> None:
    global _loops_created
    _loops_created += 1
    _base_loop_init(self)


@pytest.hookimpl(wrapper=True, trylast=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None]:
    global _loops_created
    result = yield  # every fixture is finalised first, the event loop closed
    if _loops_created or "asyncio" in item.keywords:
        # Finalise futures the test dropped, so their reports land here: only after tests
        # that ran an event loop (stdlib or uvloop). The survivors are live objects; freezing
        # them keeps the next collection to what later tests create (a full collection of
        # the whole suite's heap costs ~0.2 s; of one test's objects, milliseconds).
        gc.collect()
        gc.freeze()
    _loops_created = 0
    if _guard.records:
        report = _guard.describe()
        _guard.records.clear()
        pytest.fail(
            "unhandled asyncio errors were logged during this test:\n" + report, pytrace=False
        )
    return result


@pytest.fixture
def asyncio_errors() -> Iterator[list[logging.LogRecord]]:
    """The asyncio error records logged so far in this test; clear what the test expected."""
    yield _guard.records
