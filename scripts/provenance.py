"""Where a benchmark or analysis ran: the commit of the tree and the machine.

Every script that writes a CSV or a plot puts these in its header lines, so
that a number can be traced to the code and the hardware that produced it.
"""
import os
import platform
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def git_commit(dirty_mark=False):
    """Short hash of the repository's HEAD ("unknown" outside a git tree); with
    dirty_mark, "-dirty" appended when tracked files differ from it."""
    try:
        commit = subprocess.check_output(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], text=True,
                                         stderr=subprocess.DEVNULL).strip()
        if dirty_mark and subprocess.check_output(
                ["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"], text=True).strip():
            commit += "-dirty"
        return commit or "unknown"
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _proc_field(path, key):
    try:
        with open(path) as f:
            return next((line.split(":", 1)[1].strip() for line in f if line.startswith(key)), None)
    except OSError:
        return None


def cpu_name():
    """The CPU model of /proc/cpuinfo (platform.processor() where that is missing)."""
    return _proc_field("/proc/cpuinfo", "model name") or platform.processor() or "unknown"


def machine():
    """One line: host name, CPU model, cores and memory."""
    mem = _proc_field("/proc/meminfo", "MemTotal")
    mem = f"{int(mem.split()[0]) / 2**20:.1f} GiB" if mem else "unknown"
    return f"{platform.node()}, {cpu_name()}, {os.cpu_count()} cores, {mem} memory"
