"""What the fork server of a chain's worker processes imports once, before it forks any worker
(:func:`ndt_cli.pipeline.local_pool.start_method`); nothing else imports this module.

Each worker forked from the server has numpy, Numba and the package's tasks loaded. The server
ignores SIGTERM: a SIGTERM to the command's process group (a service stopped, ``kill -- -PGID``)
must leave the workers, which ignore it too, to finish their tasks while the command stops; the
server ends when the command does, and its workers with it.
"""

from __future__ import annotations

import importlib
import signal

WORKER_MODULES = (
    "ndt_cli.pipeline.tasks",  # the tasks of a chain
    "ndt_cli.pipeline.coarse",  # the tasks of placing scans out of order
    "ndt_cli.pipeline.local_pool",  # each worker's initialiser
)

for _name in WORKER_MODULES:
    importlib.import_module(_name)
signal.signal(signal.SIGTERM, signal.SIG_IGN)
