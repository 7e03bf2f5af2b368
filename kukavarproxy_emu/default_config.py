"""The emulator's bundled ``$CONFIG.DAT`` globals (``default_config.dat``), as text and parsed.

The globals the thesis programs use (MYAXIS, MYE6ARRAY, the path handshake, ...); the store
loads them unless ``default_config=False``. The parser is the client library's
(:mod:`pyopenshowvar.krl.datfile`), shared with the apps.
"""

from __future__ import annotations

from importlib import resources

from pyopenshowvar.krl.datfile import DatFile, parse_dat

__all__ = ["default_config_text", "load_default_config"]


def default_config_text() -> str:
    """The text of the emulator's bundled ``default_config.dat``."""
    return resources.files(__package__).joinpath("default_config.dat").read_text(encoding="utf-8")


def load_default_config() -> DatFile:
    """The parsed bundled ``default_config.dat`` (the globals the thesis programs use)."""
    return parse_dat(default_config_text(), filename="default_config.dat")
