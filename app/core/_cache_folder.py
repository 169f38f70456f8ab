"""A folder numba can cache the core's kernels in, before any of them is defined.

numba caches a kernel in the first folder it can write among ``NUMBA_CACHE_DIR``, the
``__pycache__`` beside the kernel's module and the user's cache folder; where there is none (a
read-only install run by a user without a home, as in a container run as another user), it
refuses to define a cached kernel at all, and importing the core would fail. :mod:`app.core`
imports this module first: in that case it points numba at a private folder of the system's
temporary folder instead, and says so, so that the core still loads (compiling on each start
that finds that folder empty, about a minute on 2 cores) until a writable ``NUMBA_CACHE_DIR``
is given.
"""

from __future__ import annotations

import logging
import os
import stat
import tempfile
from pathlib import Path

from numba.core import config
from numba.core.caching import FunctionCache

log = logging.getLogger(__name__)


def _probe() -> None:
    """A function of the core's folder, for asking numba where it would cache one."""


def private_folder(folder: Path) -> Path:
    """``folder``, made if need be, when only this user may write it (numba's cache holds
    pickles, which it loads); else a new private folder beside it."""
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        info = folder.lstat()
        if (
            stat.S_ISDIR(info.st_mode)
            and info.st_uid == os.getuid()
            and not (info.st_mode & (stat.S_IWGRP | stat.S_IWOTH))
        ):
            return folder
    except OSError:
        pass
    return Path(tempfile.mkdtemp(prefix=f"{folder.name}-", dir=folder.parent))


def ensure() -> Path | None:
    """Point numba at a temporary folder when it has nowhere to cache a kernel of the core;
    returns that folder, or None where numba had one."""
    try:
        FunctionCache(_probe)  # type: ignore[no-untyped-call]
        return None
    except RuntimeError:  # numba's own answer: no folder it can write
        pass
    folder = private_folder(Path(tempfile.gettempdir()) / f"efsm-numba-{os.getuid()}")
    # numba reads it as each kernel is defined
    config.CACHE_DIR = str(folder)  # type: ignore[attr-defined]
    log.warning(
        "numba has no folder it can write to cache the compiled core in (set "
        "NUMBA_CACHE_DIR to one): it goes to %s",
        folder,
    )
    return folder


ensure()
