"""Run a task graph (splatting.library.tasks) on this machine or on a Ray cluster.

local: a pool of `workers` slots on this machine; each task's work runs in its own subprocesses
       (Blender, training), so the pool only schedules and supervises.
ray:   each task is a Ray task declaring its CPUs, its dependencies passed as object refs (views
       before part training, every part before the ground-truth check), retried on failure
       (`retries`, also when its worker process dies).  Blender and training run as subprocesses of
       the Ray task.  Records are written by the task itself right after its outputs, so a killed
       driver loses nothing finished; rerunning skips what is recorded.
Both report one progress line per finished task with the running count (the aggregated bar).
"""
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
import os
import sys
import time

from cyclist_formats.errors import UserError
from splatting.library.ray_address import check_address
from splatting.library.tasks import execute

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def ray_runtime_env():
    """Workers import this checkout and keep torch single-threaded (one declared CPU each)."""
    return {"env_vars": {"PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""),
                         "OMP_NUM_THREADS": "1", "OMP_WAIT_POLICY": "PASSIVE"}}


def ensure_ray(address=None, num_cpus=None):
    """Connect to a cluster (address 'auto' or HOST:PORT) or start a local one; reuse an existing
    connection (tests start one per session)."""
    try:
        import ray
    except ImportError:
        raise UserError("--engine ray needs the ray package (pip install -r requirements.txt)") from None
    if ray.is_initialized():
        return ray
    check_address(address)
    kw = {"runtime_env": ray_runtime_env(), "log_to_driver": False, "include_dashboard": False}
    try:
        if address:
            ray.init(address=address, **kw)
        else:
            ray.init(num_cpus=num_cpus, **kw)
    except (ConnectionError, RuntimeError, ValueError) as e:
        raise UserError(f"cannot start or reach a Ray cluster ({address or 'local'}): {str(e).splitlines()[0]}") from None
    return ray


class Progress:
    def __init__(self, total, label, quiet=False):
        self.total, self.label, self.quiet, self.done, self.t0 = total, label, quiet, 0, time.time()

    def step(self, what, skipped=False):
        self.done += 1
        if not self.quiet:
            el = time.time() - self.t0
            sys.stderr.write(f"{self.label}: [{self.done}/{self.total}] {what}{' (done earlier)' if skipped else ''}, "
                             f"{el:.0f} s elapsed\n")
            sys.stderr.flush()


def run_local(graph, root, settings, workers=1, retries=1, quiet=False):
    """Run graph with `workers` tasks at a time; returns {task id: skipped}."""

    prog = Progress(len(graph), "library", quiet)
    state, tries = {}, {}
    pending = {t.id: t for t in graph}
    running = {}
    with ThreadPoolExecutor(workers) as pool:
        while pending or running:
            for tid, t in list(pending.items()):
                if len(running) >= workers:
                    break
                if all(d in state for d in t.deps):
                    running[pool.submit(execute, t, root, settings)] = t
                    del pending[tid]
            if not running:
                missing = sorted(pending)
                raise UserError(f"library: tasks {missing[:3]} wait on tasks that are not in the graph")
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in done:
                t = running.pop(fut)
                try:
                    _, skipped = fut.result()
                except UserError:
                    raise
                except Exception as e:
                    tries[t.id] = tries.get(t.id, 0) + 1
                    if tries[t.id] > retries:
                        raise UserError(f"library task {t.id} failed {tries[t.id]} times: {e}") from None
                    if not quiet:
                        sys.stderr.write(f"library: {t.id} failed ({e}); retry {tries[t.id]}/{retries}\n")
                    pending[t.id] = t
                    continue
                state[t.id] = skipped
                prog.step(t.id, skipped)
    return state


def run_ray(graph, root, settings, address=None, retries=2, quiet=False):
    """The graph as Ray tasks (dependencies as object refs); returns {task id: skipped}."""
    ray = ensure_ray(address)


    @ray.remote(max_retries=retries, retry_exceptions=True)
    def _task(task, root_, settings_, *deps):
        return task.id, execute(task, root_, settings_)[1]

    refs = {}
    for t in graph:  # graph is in dependency order
        refs[t.id] = _task.options(num_cpus=t.cpus, name=t.id).remote(t, root, settings, *[refs[d] for d in t.deps])
    prog = Progress(len(graph), "library (ray)", quiet)
    state, waiting = {}, list(refs.values())
    while waiting:
        ready, waiting = ray.wait(waiting, num_returns=1)
        try:
            tid, skipped = ray.get(ready[0])
        except ray.exceptions.RayTaskError as e:
            cause = e.cause if getattr(e, "cause", None) is not None else e
            for r in waiting:
                ray.cancel(r)
            raise UserError(f"library task failed after {retries} retries: {str(cause).splitlines()[0]}") from None
        state[tid] = skipped
        prog.step(tid, skipped)
    return state
