"""Exceptions the engine raises on purpose: each carries a message meant for the user."""


class InputError(ValueError):
    """The input cannot be used (bad file, bad cloud, bad settings). The message says what to do."""


class Cancelled(Exception):
    """The caller asked to stop; nothing was produced."""
