"""A saved model with blocks removed, for the tests that a file missing a block its layout needs
is refused in one line (``uq._models.saved.require_blocks``)."""

from __future__ import annotations

import pytest

from uq._io.errors import InputError
from uq._models import saved


def refusal_without(fit, path, monkeypatch, *blocks) -> str:
    """Save ``fit`` to ``path``, drop ``blocks`` from what is read back, and return the one line
    ``saved.load`` refuses it with."""
    path = fit.save(path, seed=3)
    attrs, groups = saved.read(path)
    groups["posterior"] = groups["posterior"].drop_vars(list(blocks))
    monkeypatch.setattr(saved, "read", lambda p: (attrs, groups))
    with pytest.raises(InputError) as err:
        saved.load(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(str(path))
    assert "saved by an older uq" in message and "fit and save it again" in message
    return message
