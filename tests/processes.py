"""Watching the processes a test started, from /proc, and waiting on events."""

import time
from pathlib import Path


def children_of(pid: int) -> list[int]:
    """Pids of the processes whose parent is `pid`."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def descendants_of(pid: int) -> list[int]:
    """Pids of the processes below `pid`: its children, theirs, and so on."""
    found, level = [], children_of(pid)
    while level:
        found += level
        level = [grandchild for child in level for grandchild in children_of(child)]
    return found


def programs_of(pid: int) -> dict[int, int]:
    """The swarm programs below process `pid`, by program number, from their process
    names (``uavtrack-<number>``, `uavtrack.agents.launcher.NAME`)."""
    found = {}
    for child in descendants_of(pid):
        try:
            name = Path(f"/proc/{child}/comm").read_text().strip()
        except OSError:
            continue
        if name.startswith("uavtrack-") and name[len("uavtrack-") :].isdigit() and alive(child):
            found[int(name[len("uavtrack-") :])] = child
    return found


def alive(pid: int) -> bool:
    """Whether process `pid` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def wait_until(condition, limit: float = 120.0, step: float = 0.1) -> bool:
    """Poll `condition` until it holds; the limit only stops a test that would hang."""
    end = time.monotonic() + limit
    while not condition():
        if time.monotonic() > end:
            return False
        time.sleep(step)
    return True
