"""A real small filesystem for full-disk tests: a tmpfs mounted on a temporary folder.

Writing to it until it is full gives the kernel's own ENOSPC (not a simulated error); deleting
the ballast file frees the space again. Mounting needs root (or CAP_SYS_ADMIN): where the test
process cannot mount, `small_disk()` skips the test, saying why.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest


class SmallDisk:
    """A mounted tmpfs of `size_mb`; `fill()` takes all its free space, `free()` gives it back."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.ballast = root / ".ballast"

    def free_bytes(self) -> int:
        return shutil.disk_usage(self.root).free

    def fill(self, leave: int = 0) -> None:
        """Write the ballast until the kernel answers ENOSPC (chunks down to one page), or until
        only `leave` bytes are free."""
        if leave:
            with open(self.ballast, "ab", buffering=0) as handle:
                handle.write(b"\0" * max(0, self.free_bytes() - leave))
            return
        chunk = 1 << 20
        with open(self.ballast, "ab", buffering=0) as handle:
            while chunk >= 4096:
                try:
                    handle.write(b"\0" * chunk)
                except OSError as exc:
                    if exc.errno != errno.ENOSPC:
                        raise
                    chunk //= 2
        assert self.free_bytes() < 8192, self.free_bytes()

    def free(self) -> None:
        self.ballast.unlink(missing_ok=True)

    def clear(self) -> None:
        """Remove everything on it (between tests sharing the mount)."""
        for path in self.root.iterdir():
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()


@contextlib.contextmanager
def small_disk(size_mb: int):
    """Mount a tmpfs of `size_mb` MiB on a new temporary folder; yields a `SmallDisk`, unmounts after."""
    root = Path(tempfile.mkdtemp(prefix="hcgym_small_disk_"))
    if os.geteuid() != 0:
        root.rmdir()
        pytest.skip("a full-disk test mounts a small tmpfs, which needs root (mount -t tmpfs)")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_mb}m,mode=0755", "tmpfs", str(root)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        root.rmdir()
        pytest.skip(f"cannot mount a tmpfs for the full-disk test: {mounted.stderr.strip()}")
    try:
        yield SmallDisk(root)
    finally:
        subprocess.run(["umount", "-l", str(root)], capture_output=True)
        with contextlib.suppress(OSError):
            root.rmdir()
