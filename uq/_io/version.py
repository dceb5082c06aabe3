"""The package version (one home: uq.__version__, pyproject.toml reads it from here) and the
date a page or a file says it was made."""

import datetime
import os

__version__ = "0.1.0"


def date_stamp() -> str:
    """Now as ``YYYY-MM-DD HH:MM UTC``, or ``SOURCE_DATE_EPOCH`` when set (reproducible outputs)."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    when = (
        datetime.datetime.fromtimestamp(int(epoch), datetime.UTC)
        if epoch and epoch.isdigit()
        else datetime.datetime.now(datetime.UTC)
    )
    return when.strftime("%Y-%m-%d %H:%M UTC")
