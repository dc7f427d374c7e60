"""Validation of names given on the command line (policies, tasks, splits, ...).

Every command that takes a name from a fixed set calls :func:`check_choice`, so a
typo always produces the same one-line error that lists what would have worked::

    Error: Invalid value for '--policy': unknown policy 'foo'; valid: gt, identity, wp

The valid set is passed in (usually from a registry), so this module imports
nothing heavy and can be used from option callbacks.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import typer

__all__ = ["check_choice", "choice_callback", "format_unknown"]


def format_unknown(kind: str, value: str, valid: Iterable[str]) -> str:
    """The error text for an unknown ``value`` of ``kind`` (e.g. kind='policy')."""
    names = sorted({str(name) for name in valid})
    listed = ", ".join(names) if names else "(none available)"
    return f"unknown {kind} {value!r}; valid: {listed}"


def check_choice(kind: str, value: str, valid: Iterable[str]) -> str:
    """Return ``value`` if it is one of ``valid``, else raise ``typer.BadParameter``.

    ``kind`` names the thing in the message ("policy", "task", "split",
    "asset source", "model", "category"). Matching is exact: names are
    identifiers, and silently accepting "WP" for "wp" would hide typos in scripts.
    """
    names = [str(name) for name in valid]
    if value in names:
        return value
    raise typer.BadParameter(format_unknown(kind, value, names))


def choice_callback(
    kind: str, valid: Iterable[str] | Callable[[], Iterable[str]]
) -> Callable[[str | None], str | None]:
    """A typer option callback that validates with :func:`check_choice`.

    ``valid`` may be a callable so a registry is only imported when the option is
    actually given (keeps ``--help`` fast). ``None`` (option not given) passes.
    """

    def _callback(value: str | None) -> str | None:
        if value is None:
            return None
        names = valid() if callable(valid) else valid
        return check_choice(kind, value, names)

    return _callback


def split_names(text: str) -> list[str]:
    """The names in a comma- or space-separated list ("wp,gf", "wp gf")."""
    return [item for item in text.replace(",", " ").split() if item]
