"""woody_common.dds_shm: Fast DDS files whose lock no process holds are removed; held or young ones are kept."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from woody_common.dds_shm import remove_stale, stale_files

OLD = time.time() - 3600.0


def make(shm, name: str, size: int = 0, old: bool = True):
    path = shm / name
    path.write_bytes(b"\0" * size)
    if old:
        os.utime(path, (OLD, OLD))
    return path


def test_only_files_of_unheld_old_locks_are_removed(tmp_path):
    dead = [make(tmp_path, "fastrtps_0123456789abcdef", 8192), make(tmp_path, "fastrtps_0123456789abcdef_el")]
    dead_port = [make(tmp_path, "fastrtps_port7411"), make(tmp_path, "fastrtps_port7411_sl"),
                 make(tmp_path, "sem.fastrtps_port7411_mutex")]
    live = [make(tmp_path, "fastrtps_fedcba9876543210", 8192), make(tmp_path, "fastrtps_fedcba9876543210_el")]
    young = [make(tmp_path, "fastrtps_port7413"), make(tmp_path, "fastrtps_port7413_el", old=False)]
    unrelated = [make(tmp_path, "fastrtps_0000000000000000"), make(tmp_path, "sem.mp-abc"), make(tmp_path, "x_el")]
    holder = subprocess.Popen([sys.executable, "-c", "import fcntl, sys, time\n"
                               f"f = open({str(live[1])!r}, 'ab'); fcntl.flock(f, fcntl.LOCK_EX)\n"
                               "print('held', flush=True); time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        assert sorted(stale_files(tmp_path)) == sorted(dead + dead_port)
        removed, freed = remove_stale(tmp_path)
    finally:
        holder.kill()
        holder.wait()
    assert removed == 5 and freed >= 8192
    assert not any(p.exists() for p in dead + dead_port)
    assert all(p.exists() for p in live + young + unrelated)
    assert sorted(stale_files(tmp_path)) == sorted(live), "the holder is gone: its files are stale now"


def test_a_missing_folder_has_nothing_stale(tmp_path):
    assert stale_files(tmp_path / "none") == [] and remove_stale(tmp_path / "none") == (0, 0)
