"""The project's error types, in a module of their own so any module can raise them
without importing the config schema (which imports the modules that define its parts)."""

from __future__ import annotations


class ConfigError(ValueError):
    """A config value is out of what is allowed; the message says which and why."""
