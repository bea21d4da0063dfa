"""Whether a run can write its result where it was told to, found before any
set-up work: the result file must be a new file (or replacing it allowed), in
a directory that exists or can be created, where a file can be created and
written now.  Checked on one rank (the file system is shared)."""
from __future__ import annotations

import errno
import os
import tempfile

from ..config.schema import ConfigError

PROBE_BYTES = 64 * 1024     # written and synced: a full disk fails here, not after the set-up


def check_output_path(path: str, key: str, *, replace: bool = False) -> None:
    """Raise ConfigError naming ``key`` (``--output`` or ``output.file``) if the
    result cannot be written at ``path``; ``replace``: an existing file may be
    replaced (``--overwrite``)."""
    full = os.path.abspath(path)
    if os.path.isdir(full):
        raise ConfigError(key, path, "a file name, not a directory")
    if os.path.lexists(full) and not replace:
        raise ConfigError(key, path, "a file that does not exist yet: add --overwrite to "
                          "replace the previous result")
    if os.path.lexists(full) and not os.path.isfile(full):
        raise ConfigError(key, path, "a regular file (it exists and is not one)")
    directory = _nearest_existing(os.path.dirname(full))
    if not os.path.isdir(directory):
        raise ConfigError(key, path, f"a path in a directory ({directory} is not one)")
    problem = _probe(directory)
    if problem:
        raise ConfigError(key, path, f"a file in a writable directory ({directory}: {problem})")


def _nearest_existing(directory: str) -> str:
    """``directory`` or its nearest ancestor that exists (the writer creates the rest)."""
    while not os.path.lexists(directory):
        parent = os.path.dirname(directory)
        if parent == directory:
            break
        directory = parent
    return directory


def _probe(directory: str) -> str:
    """Create, fill and sync a small file in ``directory``, then remove it: what
    went wrong, or ''."""
    try:
        fd, name = tempfile.mkstemp(prefix=".distcloth-probe-", dir=directory)
    except OSError as exc:
        return _reason(exc)
    try:
        os.write(fd, b"\0" * PROBE_BYTES)
        os.fsync(fd)
        return ""
    except OSError as exc:
        return _reason(exc)
    finally:
        os.close(fd)
        os.unlink(name)


def _reason(exc: OSError) -> str:
    if exc.errno == errno.ENOSPC:
        return "no space left on the device"
    return exc.strerror or str(exc)
