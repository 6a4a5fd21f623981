"""Command-line flags for the fields of a settings dataclass, one flag per field.

``--radius-mode`` for ``radius_mode``: type, choices, default and help all come from the field
and its :class:`~engine.settings.SettingInfo`, so a new setting is a new flag with no edit here.
"""

import argparse
from dataclasses import fields

from ..settings import ReconstructSettings, setting_info


def flag(name: str) -> str:
    """The command-line flag of a setting: ``radius_mode`` → ``--radius-mode``."""
    return "--" + name.replace("_", "-")


def add_settings_arguments(parser, settings_type=ReconstructSettings,
                           use_defaults: bool = True) -> None:
    """Add a flag per field of ``settings_type`` to an ``argparse`` parser or group.

    use_defaults: False leaves an absent flag as None (the caller fills it from elsewhere, as
    the batch script does from the open file's panel); the help still names the default.
    """
    for item in fields(settings_type):
        info = setting_info(item)
        default = item.default
        options = {"dest": item.name, "default": default if use_defaults else None,
                   "help": f"{info.cli_help} (default {default})".replace("%", "%%")}
        if isinstance(default, bool):
            options["action"] = argparse.BooleanOptionalAction
        else:
            options["type"] = type(default)
        if info.choices:
            options["choices"] = info.values
        if info.implies:
            defaults = {f.name: f.default if use_defaults else None for f in fields(settings_type)}
            options["action"] = _implying(info.implies, defaults)
        parser.add_argument(flag(item.name), **options)


def _implying(implies, defaults: dict):
    """An argparse action that stores its value and also sets each ``(setting, value)`` of
    ``implies`` whose flag was not given before it (it still holds its default)."""

    class Implying(argparse.Action):
        def __call__(self, parser, namespace, values, option_string=None):
            setattr(namespace, self.dest, values)
            for name, value in implies:
                if getattr(namespace, name) == defaults[name]:
                    setattr(namespace, name, value)

    return Implying
