"""The viewer's error type (one place, imported by every viewer module)."""

from __future__ import annotations

from se3dyn.errors import Se3dynError

__all__ = ["ViewerError"]


class ViewerError(Se3dynError, ValueError):
    """Bad input to the viewer (missing mesh file, unknown channel, model not matching the
    results); the message is one line naming the item, the field, what was expected and got."""
