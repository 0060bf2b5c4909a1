"""Fast DDS shared-memory files left behind by processes that died, found by their lock files and removed.

Fast DDS keeps a lock file beside each shared-memory segment and port
(``fastrtps_<id>_el``, ``fastrtps_port<N>_el`` or ``_sl``) and holds an
exclusive ``flock`` on it while its process lives. A process killed outright
(``kill -9``, a crash) leaves its files behind: each segment up to the
segment size of config/fastdds.xml (256 MB) of memory in /dev/shm, for good.
A lock file nobody holds marks such a leftover (the rule of Fast DDS's own
``fastdds shm clean``, whose command is not in the PyPI wheels). A lock file
younger than ``min_age_s`` is left alone: its process may be starting and not
hold the lock yet.
"""

from __future__ import annotations

import fcntl
import re
import time
from pathlib import Path

SHM_DIR = Path("/dev/shm")
LOCK_FILE = re.compile(r"^fastrtps_(port\d{1,5}|[0-9a-z]{16})_(el|sl)$")
MIN_AGE_S = 30.0


def _held(lock: Path) -> bool:
    """Whether a live process holds ``lock`` (an exclusive flock on it fails)."""
    try:
        with lock.open("ab") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    return False


def _files_of(lock: Path) -> list[Path]:
    """The lock file, its segment or port file and, for a port, its named semaphore."""
    base = lock.name[:-3]
    files = [lock, lock.with_name(base)]
    if base.startswith("fastrtps_port"):
        files.append(lock.with_name(f"sem.{base}_mutex"))
    return files


def stale_files(shm_dir: Path = SHM_DIR, min_age_s: float = MIN_AGE_S) -> list[Path]:
    """The files of every segment and port whose lock file is older than ``min_age_s`` and held by no process."""
    now = time.time()
    stale: list[Path] = []
    try:
        locks = sorted(p for p in shm_dir.iterdir() if LOCK_FILE.match(p.name))
    except OSError:
        return []
    for lock in locks:
        try:
            young = now - lock.stat().st_mtime < min_age_s
        except OSError:
            continue  # removed meanwhile by its own process
        if not young and not _held(lock):
            stale += [f for f in _files_of(lock) if f.exists()]
    return stale


def remove_stale(shm_dir: Path = SHM_DIR, min_age_s: float = MIN_AGE_S) -> tuple[int, int]:
    """Remove what :func:`stale_files` finds; returns (files removed, bytes of memory freed)."""
    removed = freed = 0
    for path in stale_files(shm_dir, min_age_s):
        try:
            freed += path.stat().st_blocks * 512
            path.unlink()
            removed += 1
        except OSError:
            continue
    return removed, freed
