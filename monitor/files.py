"""Files the user keeps (gains, plants): written whole or not at all, with the mode any file of theirs gets.

Why a temporary file and a rename: a design or an identification that is interrupted, or a full disk, must
not leave a half-written file where the old one was; ``os.replace`` is atomic on one file system. Why
``fchmod``: ``mkstemp`` creates 0600, but a gains or plant file is no secret, and a colleague reading it
should get what the user's umask gives any other file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["write_text_atomically"]


def write_text_atomically(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` (UTF-8) through a temporary file in the same directory; OSError on failure."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, dir=path.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
