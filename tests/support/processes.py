"""Child processes in tests: stopped politely, then firmly, never left behind."""

from __future__ import annotations

import subprocess


def stop_process(popen: subprocess.Popen) -> int | None:
    """SIGTERM, up to 10 s for a clean exit, then SIGKILL; the exit code."""
    if popen.poll() is None:
        popen.terminate()
        try:
            popen.wait(10)
        except subprocess.TimeoutExpired:
            popen.kill()
            popen.wait(5)
    return popen.returncode
