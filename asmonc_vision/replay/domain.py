"""A ROS domain id per `asmonc run`, so that runs side by side do not hear each other."""
from __future__ import annotations

import tempfile
from pathlib import Path

MAX_DOMAIN_ID = 101   # the highest domain id that is portable across DDS vendors
#: The highest domain id a DDS participant can take on Linux (ROS 2 "The ROS_DOMAIN_ID"):
#: a ROS_DOMAIN_ID set above `MAX_DOMAIN_ID` is honoured up to this.
MAX_LINUX_DOMAIN_ID = 232


def domain_search_limit(preferred: int) -> int:
    """The last domain id `claim_domain` tries from ``preferred``: `MAX_DOMAIN_ID`, or
    `MAX_LINUX_DOMAIN_ID` for a preferred id already above the portable range."""
    return MAX_DOMAIN_ID if preferred <= MAX_DOMAIN_ID else MAX_LINUX_DOMAIN_ID


def claim_domain(preferred: int, lock_dir: Path | None = None):
    """Claim a ROS domain id for one `asmonc run`, so that runs started side by side on one
    machine do not hear each other's topics (each would see the other's /obstacles).

    Tries ``preferred``, then the ids above it up to `domain_search_limit`, taking an exclusive
    ``flock`` on ``<lock_dir>/asmonc-run-domain-<id>.lock`` (the system temp dir by
    default); the lock lasts as long as the returned file object is open, and the OS
    releases it if the process dies. Other ROS programs in the domain are not seen: this
    only keeps asmonc runs apart.

    Returns:
        (domain id, open lock file), or (None, None) when every id is taken.
    """
    import fcntl
    lock_dir = Path(lock_dir or tempfile.gettempdir())
    for domain in range(max(0, preferred), domain_search_limit(preferred) + 1):
        f = open(lock_dir / f'asmonc-run-domain-{domain}.lock', 'a')
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        return domain, f
    return None, None
