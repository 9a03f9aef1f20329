"""Sweeps on a Ray cluster: each of the plan's map groups is one Ray task.

``dsm run CONFIG --cluster ADDRESS`` (or ``[execution] backend = "ray"``, ``address``) sends
each map group (scene x light x view x resolution x culling: one map build, then all its
schemes, filters and formats) to a Ray task, so a task builds its map once and reuses its
compiled kernels for every case. ``--cluster local`` starts a Ray instance on this machine.

A worker sets the Mitsuba variant and Dr.Jit's thread count from its task's CPU allotment
(``cpus_per_task``; a cuda variant's task asks for ``gpus_per_task`` of a GPU, fractions
allowed); Dr.Jit keeps its kernel cache where it always does, on the worker's local disk
(``~/.drjit`` of the worker's user). A task runs the local runner (:class:`dsm.experiment.runner.Runner`)
on its one map group in a temporary folder and returns its rows, status entries, oracle rows,
curves, map record, rays and image files. A task that raises or loses its worker is retried
once by Ray, then recorded as failed with its cases while the rest finish.

The driver writes the folder as a local run does: the plan's case ids, the same rows in the
same order (a group's rows once every earlier group's are written), one progress bar. Timings,
peak memory and compile counts differ by nature. run.json's ``rays`` are the plan's work
(G-buffer and reference counted once per scene and light, as a local run counts them);
``nodes`` gives each node's own ray counts (which repeat the G-buffer and reference of every
group a node ran) and each case's status entry names its node.
"""
from __future__ import annotations

import os
import socket
import tempfile
from pathlib import Path

from ..report import io as report
from .runner import Runner


def _ray():
    try:
        import ray
    except ImportError:
        from ..core.env import SetupError
        raise SetupError("Ray is not installed: pip install 'dsm[cluster]' (or pip install ray)") from None
    return ray


def _start(address: str | None, cpus: int | None = None):
    ray = _ray()
    if ray.is_initialized():
        return ray
    if address in (None, "local"):
        ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False, logging_level="error")
    else:
        ray.init(address=address, include_dashboard=False, log_to_driver=False, logging_level="error")
    return ray


ADDRESSES = ("local", "auto", "ray://host:port", "host:port")


def connect(address: str | None, cpus: int | None = None, source: str = "arguments", key: str = "--cluster"):
    """Start (``local``) or join the Ray cluster at ``address`` before any work, so that a wrong
    address is one line (a ConfigError of ``source`` naming ``key``; Ray's client package missing
    is a SetupError) instead of a traceback after the results folder is written. Returns ray."""
    from ..core.env import SetupError
    from ..core.types import ConfigError
    ray = _ray()
    if address not in (None, "local", "auto") and not ray.is_initialized():
        # Ray retries an unreachable host:port for minutes: knock once first
        host, _, port = address.removeprefix("ray://").rpartition(":")
        if not host or not port.isdigit():
            raise ConfigError(source, key, f"expected local, auto or a Ray address host:port (ray://host:port for "
                              f"Ray's client), got {address!r}", ADDRESSES)
        try:
            socket.create_connection((host, int(port)), timeout=5).close()
        except OSError as e:
            raise ConfigError(source, key, f"nothing answers at {host}:{port} ({e.strerror or e}); is the Ray "
                              "cluster up?", ADDRESSES) from None
    try:
        return _start(address, cpus)
    except Exception as e:            # Ray raises ConnectionError, ValueError, RuntimeError, TimeoutError...
        msg = " ".join(str(e).split()) or type(e).__name__
        if "requires pip package" in msg:
            raise SetupError(f"{key} {address}: Ray's client is not installed: pip install 'ray[client]'") from None
        if ray.is_initialized():
            ray.shutdown()
        raise ConfigError(source, key, f"cannot start or reach a Ray cluster at {address!r}: {msg[:300]}",
                          ADDRESSES) from None


def local_resources(cpus: int | None = None) -> dict | None:
    """The CPUs and GPUs of a Ray instance started here with ``cpus`` CPUs (None: Ray's count), resolved as
    ray.init resolves them but without starting it; None where this Ray release resolves them elsewhere
    (Ray's own class for it is internal: then the check waits for the started instance), or where Ray
    already runs in this process or RAY_ADDRESS names a cluster (ray.init joins that one instead)."""
    if _ray().is_initialized() or os.environ.get("RAY_ADDRESS"):
        return None
    try:
        from ray._private.resource_and_label_spec import ResourceAndLabelSpec as Spec      # recent Ray (2.60 here)
    except ImportError:
        try:
            from ray._private.resource_spec import ResourceSpec as Spec                     # older Ray releases
        except ImportError:
            return None
    try:
        spec = Spec(num_cpus=cpus).resolve(is_head=True, node_ip_address="127.0.0.1")
        return {"CPU": float(spec.num_cpus), "GPU": float(spec.num_gpus or 0)}
    except Exception:                 # an internal API that moved: no early answer, the started one's instead
        return None


def check_resources(execution, variant: str, source: str, have: dict | None = None):
    """SetupError naming the key and what the cluster has when one task asks for more CPUs or
    GPUs than the whole cluster holds (Ray would wait for them forever). ``have``: the cluster's
    resources where known before it starts (local_resources); else the connected cluster's, and Ray
    is shut down first, so no process is left behind."""
    from ..core.env import SetupError
    ray = None if have is not None else _ray()
    if ray is not None:
        have = ray.cluster_resources()
    gpus = execution.gpus_per_task or (1.0 if (variant or "").startswith("cuda") else 0.0)
    for key, want, name in (("execution.cpus_per_task", execution.cpus_per_task, "CPU"),
                            ("execution.gpus_per_task", gpus, "GPU")):
        if want and want > have.get(name, 0.0):
            if ray is not None:
                ray.shutdown()
            raise SetupError(f"{source}: {key} = {want:g} asks each task for more {name}s than the Ray cluster has "
                             f"({have.get(name, 0.0):g}): its tasks would wait forever")


def run_group(cfg, index: int, variant, threads: int, kept: dict) -> dict:
    """One map group of the plan, run in this process (a Ray worker): the runner's own stages on
    a temporary folder, returned as plain data for the driver."""
    from ..core import env
    env.use_variant(variant, max(1, threads))
    with tempfile.TemporaryDirectory(prefix="dsm-task-") as tmp:
        r = Runner(cfg, Path(tmp), variant, progress=False, keep_images=False)
        r.run_maps([r.plan.maps[index]], kept)
        # the files the cases wrote as they ran (case and cascade images), by path under images/ (a motion
        # case's GIF is drawn by the driver, from the GifFrames in the task's record)
        images = {str(p.relative_to(r.out / "images")): p.read_bytes()
                  for p in sorted((r.out / "images").rglob("*")) if p.is_file()}
    node = socket.gethostname()
    try:
        node = f"{node}:{_ray().get_runtime_context().get_node_id()[:8]}"
    except Exception:
        pass
    return {"record": r.record, "images": images, "node": node, "pid": os.getpid()}


class ClusterRunner(Runner):
    """The runner with its map groups sent to Ray tasks; the driver writes every file."""

    def __init__(self, config, out, address=None, variant=None, progress=True, resume_previous=False,
                 local_cpus: int | None = None, report: bool = True):
        super().__init__(config, out, variant, progress, keep_images=False, resume_previous=resume_previous,
                         report=report)
        self.plan.stacks = []       # a Ray task runs one map: [timing] builds = "together" stacks nothing here
        self.address = address if address is not None else (config.execution.address or "local")
        self.local_cpus = local_cpus
        self.nodes = {}

    def _run_plan(self, maps=None):
        ray = _start(self.address, self.local_cpus)
        ex = self.cfg.execution
        gpus = ex.gpus_per_task or (1.0 if self.variant.startswith("cuda") else 0.0)
        task = ray.remote(run_group).options(num_cpus=ex.cpus_per_task, num_gpus=gpus, max_retries=1,
                                             retry_exceptions=True)
        for spec in self.cfg.scenes:
            if spec.missing:
                self.record.status.append({"what": f"scene {spec.label}", "status": "skipped", "error": spec.missing})
        cfg_ref = ray.put(self.cfg)
        threads = max(1, int(ex.cpus_per_task))
        pending = {}
        for i, m in enumerate(self.plan.maps):
            if maps is not None and m not in maps:
                continue
            ids = [c for c, _ in list(self.keys.items())[self.first_case[i]:self.first_case[i + 1]]]
            kept = {self.keys[c]: self.kept[self.keys[c]] for c in ids if self.keys[c] in self.kept}
            pending[task.remote(cfg_ref, i, self.variant, threads, kept)] = i
        order = sorted(pending.values())
        done, nxt = {}, 0
        self.seen = set()
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                i = pending.pop(ref)
                try:
                    done[i] = ray.get(ref)
                except Exception as e:          # after Ray's one retry: the group's cases fail, the rest go on
                    done[i] = e
                self.bar.update(self.plan.maps[i].cases)
            while nxt < len(order) and order[nxt] in done:
                self._merge(order[nxt], done.pop(order[nxt]))
                nxt += 1

    def _merge(self, i, res):
        m = self.plan.maps[i]
        what = f"scene {m.scene} light {m.light} view {m.view} map {m.resolution} culling {m.culling}"
        if isinstance(res, Exception):
            self.record.status.append({"what": what, "status": "failed", "error": f"{type(res).__name__}: {res}",
                                       "cases": m.cases})
            self._write_run_json()
            return
        node, task = res["node"], res["record"]
        for name, data in res["images"].items():
            (self.out / "images" / name).parent.mkdir(parents=True, exist_ok=True)
            with report.atomic(self.out / "images" / name) as tmp:
                tmp.write_bytes(data)
        for row in task.rows:
            self.sink.csv.write(row)
        self.record.merge(task, node, res["pid"], self.seen, m.scene, (m.scene, m.light))
        per = self.nodes.setdefault(node, {"rays": {}, "cases": 0, "groups": 0})
        for k, v in task.rays.items():
            per["rays"][k] = per["rays"].get(k, 0) + v
        per["cases"] += len(task.rows)
        per["groups"] += 1
        self._write_run_json()

    def _launches(self) -> dict:
        """Kernel launches are counted where they happen: in the tasks, not here (null)."""
        return {"outside_repeats": None, "timed_repeats": None, "outside_per_case": None}

    def _run_json(self):
        info = super()._run_json()
        info["backend"] = {"name": "ray", "address": self.address}
        info["nodes"] = getattr(self, "nodes", {})
        return info


def run(config, out, address=None, variant=None, progress=True, resume_previous=False, local_cpus=None,
        report: bool = True):
    """Run a prepared Config on Ray (see the module's text) and return its Results (``report=False``: no figures)."""
    return ClusterRunner(config, Path(out), address, variant, progress, resume_previous, local_cpus, report).run()
