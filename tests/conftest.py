"""Shared fixtures: the in-process emulator (real TCP on 127.0.0.1, ephemeral port)."""

pytest_plugins = ["kukavarproxy_emu.testing"]
