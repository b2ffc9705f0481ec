"""Run independent tasks on worker processes of this machine or of a Ray cluster, results in task order.

``ParallelConfig`` (config group ``parallel``) says where: ``workers: 1`` runs in this process;
``backend: local`` starts ``workers`` processes here (spawned: MuJoCo's renderer and GTSAM do not
survive a fork); ``backend: ray`` sends the tasks to a Ray cluster (``ray.init(address=...)``;
Ray is the optional extra ``vical[ray]``). The same task function runs unchanged everywhere; it
must be a module-level function and its tasks and results picklable. Results come back in the
order of the tasks, so a parallel run gives exactly what a serial run gives.
"""

from __future__ import annotations

from vical.parallel.pool import (
    MAX_WORKERS,
    ParallelConfig,
    WorkerCrashed,
    check_ray_address,
    connect_ray,
    imap_ordered,
    single_threaded_children,
)

__all__ = [
    "MAX_WORKERS",
    "ParallelConfig",
    "WorkerCrashed",
    "check_ray_address",
    "connect_ray",
    "imap_ordered",
    "single_threaded_children",
]
