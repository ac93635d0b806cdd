"""MLflow tracking: the only module that talks to MLflow.

One MLflow run per stage invocation, in the experiment ``socnav-wm`` (or
``MLFLOW_EXPERIMENT_NAME``), at ``MLFLOW_TRACKING_URI`` or else ``sqlite:///mlflow.db`` in the
working directory (set explicitly: MLflow's own default has changed between versions).

mlflow is imported inside the functions that need it: the import takes seconds, and neither
``socnav-wm --help`` nor a ``--no-tracking`` run should pay for it.
"""

from __future__ import annotations

import contextlib
import contextvars
import getpass
import json
import logging
import os
import re
import socket
import ssl
import subprocess
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from socnav_wm.config import flatten
from socnav_wm.tracking_models import DESCRIPTION_TAG, EXPERIMENT_DESCRIPTION, HEADLINE_TAG

__all__ = [
    "DEFAULT_TRACKING_URI",
    "EXPERIMENT_NAME",
    "Run",
    "TrackingError",
    "check_tracking",
    "experiment_name",
    "nested_under",
    "stage_run",
    "tracking_uri",
]

DEFAULT_TRACKING_URI = "sqlite:///mlflow.db"
EXPERIMENT_NAME = "socnav-wm"
EXPERIMENT_KIND_TAG = "mlflow.experimentKind"
EXPERIMENT_KIND = "custom_model_development"
HEALTH_TIMEOUT_S = 3.0

# The most conservative limits across MLflow server versions (older servers cap a param value at
# 500 characters; a batch at 100 params/tags and 1000 metrics).
_MAX_PARAM_VALUE = 500
_MAX_TAG_VALUE = 5000
_PARAMS_PER_BATCH = 100
_METRICS_PER_BATCH = 1000
# Metrics are buffered and sent in batches: one SQLite transaction per training step would cost
# more than the step. A live MLflow UI lags by at most this much.
_METRICS_FLUSH_S = 5.0

_HINT = "set MLFLOW_TRACKING_URI or pass --no-tracking"

Arrays = Mapping[str, Any]
"""Numpy arrays by name (a model's example inputs or outputs)."""

log = logging.getLogger(__name__)


class TrackingError(RuntimeError):
    """The tracking backend cannot be used; the message is one line with the way out."""


def repository_root() -> Path:
    """Where the default store lives: the DVC repository's root.

    ``DVC_ROOT`` when DVC runs the stage (under ``dvc exp run --queue`` or ``--temp`` it names
    the user's repository, not DVC's temporary workspace, which is deleted afterwards); else
    the nearest folder above the working directory holding ``dvc.yaml`` or ``.git``; else the
    working directory.
    """
    if os.environ.get("DVC_ROOT"):
        return Path(os.environ["DVC_ROOT"]).resolve()
    here = Path.cwd().resolve()
    for folder in (here, *here.parents):
        if (folder / "dvc.yaml").is_file() or (folder / ".git").exists():
            return folder
    return here


def tracking_uri() -> str:
    """``MLFLOW_TRACKING_URI`` if set (and not empty), else ``mlflow.db`` at the repository's
    root (:func:`repository_root`) as an absolute SQLite URI."""
    uri = os.environ.get("MLFLOW_TRACKING_URI", "").strip()
    if uri:
        return uri
    return f"sqlite:///{repository_root() / DEFAULT_TRACKING_URI.removeprefix('sqlite:///')}"


def experiment_name() -> str:
    """``MLFLOW_EXPERIMENT_NAME`` if set, else ``socnav-wm``."""
    return os.environ.get("MLFLOW_EXPERIMENT_NAME", "").strip() or EXPERIMENT_NAME


# ---------------------------------------------------------------------------------------------
# Pre-flight check
# ---------------------------------------------------------------------------------------------


def check_tracking(uri: str | None = None, *, timeout_s: float = HEALTH_TIMEOUT_S) -> None:
    """Fail fast, before any work, when runs could not be recorded at ``uri``.

    - ``sqlite:///path``: the database's directory must exist and be writable (and the file, if
      it exists);
    - ``http(s)://``: ``GET <uri>/health`` must answer within ``timeout_s``;
    - ``file:`` URIs and plain paths: the directory (or its nearest existing parent) must be
      writable.

    Other schemes (postgresql, databricks, ...) are not checked. Raises :class:`TrackingError`.
    """
    uri = uri or tracking_uri()
    scheme = urllib.parse.urlsplit(uri).scheme.lower()
    if scheme == "sqlite":
        _check_sqlite(uri)
    elif scheme in ("http", "https"):
        _check_http(uri, timeout_s)
    elif scheme == "file" or scheme == "" or len(scheme) == 1:  # 1 letter: a Windows drive
        _check_directory(uri, _file_uri_path(uri))


STORE_LOCK_TIMEOUT_S = 300.0
"""How long a stage waits for another process to finish creating a SQLite store."""


def _sqlite_database(uri: str) -> Path | None:
    """The database of ``sqlite:///relative.db`` or ``sqlite:////absolute.db`` (maybe with a
    ``?query``); None for another scheme or in memory (``sqlite://``)."""
    if not uri.lower().startswith("sqlite://"):
        return None
    rest = uri[len("sqlite://") :].split("?", 1)[0]
    database = rest[1:] if rest.startswith("/") else rest
    return None if database in ("", ":memory:") else Path(database)


def _check_sqlite(uri: str) -> None:
    db_path = _sqlite_database(uri)
    if db_path is None:
        return
    directory = db_path.parent.resolve()
    if not directory.is_dir():
        _fail(uri, f"directory {directory} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        _fail(uri, f"directory {directory} is not writable")
    if db_path.exists() and not os.access(db_path, os.R_OK | os.W_OK):
        _fail(uri, f"database {db_path.resolve()} is not writable")


def _file_uri_path(uri: str) -> Path:
    if uri.lower().startswith("file:"):
        parts = urllib.parse.urlsplit(uri)
        return Path(urllib.request.url2pathname(parts.path))
    return Path(uri)


def _check_directory(uri: str, directory: Path) -> None:
    from socnav_wm.io import nearest_existing

    existing = nearest_existing(directory)  # MLflow creates the missing levels
    if not existing.is_dir():
        _fail(uri, f"{existing} is not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        _fail(uri, f"directory {existing} is not writable")


def _check_http(uri: str, timeout_s: float) -> None:
    url = uri.rstrip("/") + "/health"
    try:
        context = _tls_context() if url.lower().startswith("https:") else None
        with urllib.request.urlopen(url, timeout=timeout_s, context=context) as response:
            response.read(256)
    except urllib.error.HTTPError as exc:
        if exc.code in (401, 403):
            return  # the server is up; credentials are MLflow's business, not a reachability one
        _fail(uri, f"answered HTTP {exc.code} on /health", server=True)
    except urllib.error.URLError as exc:
        _fail(uri, f"is unreachable ({_reason(exc.reason, timeout_s)})", server=True)
    except (TimeoutError, OSError) as exc:
        _fail(uri, f"is unreachable ({_reason(exc, timeout_s)})", server=True)


def _tls_context() -> ssl.SSLContext | None:
    """MLflow's own TLS settings, so that the check agrees with what MLflow will do."""
    if os.environ.get("MLFLOW_TRACKING_INSECURE_TLS", "").lower() == "true":
        return ssl._create_unverified_context()  # noqa: S323 - the user asked for it
    if os.environ.get("MLFLOW_TRACKING_SERVER_CERT_PATH"):
        return ssl.create_default_context(cafile=os.environ["MLFLOW_TRACKING_SERVER_CERT_PATH"])
    return None


def _reason(reason: object, timeout_s: float) -> str:
    if isinstance(reason, ConnectionRefusedError):
        return "connection refused"
    if isinstance(reason, TimeoutError | socket.timeout):
        return f"no answer within {timeout_s:g} s"
    if isinstance(reason, socket.gaierror):
        return "unknown host"
    if isinstance(reason, ssl.SSLError):
        return f"TLS error: {reason.reason or reason}"
    if isinstance(reason, OSError) and reason.strerror:
        return reason.strerror.lower()
    return " ".join(str(reason).split()) or type(reason).__name__


def _fail(uri: str, problem: str, *, server: bool = False) -> None:
    what = "MLflow tracking server" if server else "MLflow tracking store"
    separator = " " if server else ": "
    raise TrackingError(f"{what} {_redact(uri)}{separator}{problem}; {_HINT}")


def _redact(uri: str) -> str:
    """The URI without a password, for messages."""
    parts = urllib.parse.urlsplit(uri)
    if parts.password is None:
        return uri
    host = parts.hostname or ""
    if parts.port:
        host = f"{host}:{parts.port}"
    return urllib.parse.urlunsplit(parts._replace(netloc=f"{parts.username}:***@{host}"))


# ---------------------------------------------------------------------------------------------
# Runs
# ---------------------------------------------------------------------------------------------


class Run:
    """A stage's handle on its MLflow run.

    This base class is the disabled form (``--no-tracking``): every method does nothing, so stage
    code never checks whether tracking is on.
    """

    run_id: str | None = None

    def log_metrics(self, metrics: Mapping[str, float], step: int | None = None) -> None:
        """Record metric values (at training step ``step``, or 0)."""

    def log_params(self, params: Mapping[str, Any]) -> None:
        """Record extra parameters, flattened (``{"vae": {"x": 1}}`` becomes ``vae.x``)."""

    def log_artifact(self, path: str | os.PathLike[str], artifact_path: str | None = None) -> None:
        """Copy a file or a directory into the run's artifacts (under ``artifact_path``)."""

    def log_figure(self, figure: Any, name: str) -> None:
        """Save a matplotlib figure as the artifact ``name`` (e.g. ``figures/loss.png``)."""

    def log_text(self, text: str, name: str) -> None:
        """Save ``text`` as the artifact ``name``."""

    def log_model(
        self,
        module: Any,
        inputs: Arrays,
        outputs: Arrays,
        name: str = "model",
        *,
        model_type: str | None = None,
        tags: Mapping[str, Any] | None = None,
        variable_axes: int = 1,
    ) -> str | None:
        """The logged model ``name`` of this run, and its id (None when tracking is off):
        :func:`socnav_wm.tracking_models.log_logged_model`."""
        return None

    def set_tag(self, key: str, value: Any) -> None:
        """Set a run tag."""

    def log_headline(
        self, metrics: Mapping[str, float], units: Mapping[str, str] | None = None
    ) -> None:
        """The few metrics a user compares first: logged (step 0) unless they already are,
        named in order in the tag ``headline_metrics``, and written with their ``units`` as the
        run's description, which MLflow's UI shows above everything else."""

    def flush(self) -> None:
        """Send buffered metrics now."""

    def link_runs(self, key: str, stages: Sequence[str]) -> list[str]:
        """Tag this run with the ids of the latest finished run of each of ``stages`` (e.g. the
        trainings whose weights an evaluation uses), as ``key`` = comma-separated ids; returns
        the ids (empty when tracking is off or no such run exists)."""
        return []


class _MlflowRun(Run):
    """A live MLflow run, written through an explicit ``MlflowClient`` (no global state)."""

    def __init__(self, client: Any, run_id: str) -> None:
        self._client = client
        self.run_id = run_id
        self._pending: list[Any] = []
        self._last_flush = time.monotonic()
        self._final: set[str] = set()  # the metrics logged at step 0

    def log_metrics(self, metrics: Mapping[str, float], step: int | None = None) -> None:
        from mlflow.entities import Metric

        timestamp = int(time.time() * 1000)
        if not step:
            self._final.update(map(str, metrics))
        self._pending.extend(
            Metric(key=str(key), value=float(value), timestamp=timestamp, step=int(step or 0))
            for key, value in metrics.items()
        )
        if (
            len(self._pending) >= _METRICS_PER_BATCH
            or time.monotonic() - self._last_flush >= _METRICS_FLUSH_S
        ):
            self.flush()

    def flush(self) -> None:
        pending, self._pending = self._pending, []
        for start in range(0, len(pending), _METRICS_PER_BATCH):
            self._client.log_batch(self.run_id, metrics=pending[start : start + _METRICS_PER_BATCH])
        self._last_flush = time.monotonic()

    def log_params(self, params: Mapping[str, Any]) -> None:
        from mlflow.entities import Param

        entries = [Param(key, _param_value(value)) for key, value in flatten(params).items()]
        for start in range(0, len(entries), _PARAMS_PER_BATCH):
            self._client.log_batch(self.run_id, params=entries[start : start + _PARAMS_PER_BATCH])

    def log_artifact(self, path: str | os.PathLike[str], artifact_path: str | None = None) -> None:
        local = Path(path)
        if local.is_dir():
            self._client.log_artifacts(self.run_id, str(local), artifact_path)
        else:
            self._client.log_artifact(self.run_id, str(local), artifact_path)

    def log_figure(self, figure: Any, name: str) -> None:
        self._client.log_figure(self.run_id, figure, name)

    def log_text(self, text: str, name: str) -> None:
        self._client.log_text(self.run_id, text, name)

    def log_model(
        self,
        module: Any,
        inputs: Arrays,
        outputs: Arrays,
        name: str = "model",
        *,
        model_type: str | None = None,
        tags: Mapping[str, Any] | None = None,
        variable_axes: int = 1,
    ) -> str | None:
        from socnav_wm.tracking_models import log_logged_model

        self.flush()  # the final metrics, linked to the model, must be in the store first
        return log_logged_model(
            self._client,
            self.run_id,
            module,
            (inputs, outputs, variable_axes),
            name=name,
            model_type=model_type,
            tags={str(k): _truncate(str(v), _MAX_TAG_VALUE) for k, v in (tags or {}).items()},
        )

    def set_tag(self, key: str, value: Any) -> None:
        self._client.set_tag(self.run_id, key, _truncate(str(value), _MAX_TAG_VALUE))

    def log_headline(
        self, metrics: Mapping[str, float], units: Mapping[str, str] | None = None
    ) -> None:
        values = {str(key): float(value) for key, value in metrics.items()}
        self.log_metrics({key: value for key, value in values.items() if key not in self._final})
        self.set_tag(HEADLINE_TAG, ",".join(values))
        units = units or {}
        shown = (f"{k} {v:.4g} {units.get(k, '')}".rstrip() for k, v in values.items())
        self.set_tag(DESCRIPTION_TAG, "; ".join(shown))

    def link_runs(self, key: str, stages: Sequence[str]) -> list[str]:
        experiment = self._client.get_run(self.run_id).info.experiment_id
        ids = []
        for stage in stages:
            found = self._client.search_runs(
                [experiment],
                filter_string=f"tags.stage = '{stage}' and attributes.status = 'FINISHED'",
                order_by=["attributes.end_time DESC"],
                max_results=1,
            )
            ids += [run.info.run_id for run in found]
        if ids:
            self.set_tag(key, ",".join(ids))
        return ids


_PARENT: contextvars.ContextVar[tuple[str, dict[str, str]] | None] = contextvars.ContextVar(
    "socnav_wm_parent_run", default=None
)


@contextlib.contextmanager
def nested_under(run_id: str | None, tags: Mapping[str, Any] | None = None) -> Iterator[None]:
    """Make every run :func:`stage_run` starts inside the block a child of MLflow run ``run_id``
    (MLflow's ``mlflow.parentRunId`` tag, which its UI nests by) carrying ``tags`` too (a sweep's
    grid values). ``run_id=None`` (tracking off) changes nothing."""
    if run_id is None:
        yield
        return
    token = _PARENT.set((run_id, {str(k): str(v) for k, v in (tags or {}).items()}))
    try:
        yield
    finally:
        _PARENT.reset(token)


@contextlib.contextmanager
def stage_run(
    stage: str,
    params: Mapping[str, Any],
    *,
    enabled: bool = True,
    run_name: str | None = None,
) -> Iterator[Run]:
    """One MLflow run around a stage invocation.

    Logs ``params`` flattened (``vae.kl_weight``; the full, untruncated dict also as the
    ``params.json`` artifact) and the tags ``stage``, ``git_commit`` and, under ``dvc exp run``,
    ``dvc_exp_name``. The run ends FINISHED, or FAILED when the block raises (KILLED on Ctrl-C),
    and the exception propagates. With ``enabled=False`` the yielded :class:`Run` does nothing
    and mlflow is never imported.
    """
    if not enabled:
        yield Run()
        return

    uri = tracking_uri()
    check_tracking(uri)
    _quiet_database_logs()
    from mlflow import MlflowClient

    from socnav_wm.locks import LockTimeout, waiting_lock

    try:  # opening a SQLite store creates or migrates it: one process at a time (locks.py)
        with waiting_lock(_sqlite_database(uri), STORE_LOCK_TIMEOUT_S):
            client = MlflowClient(tracking_uri=uri)
            experiment_id = _experiment_id(client, uri)
    except LockTimeout:
        raise TrackingError(f"{_redact(uri)}: another process kept creating it; {_HINT}") from None
    commit = _git_commit()
    tags = {
        "stage": stage,
        "git_commit": commit,
        "mlflow.source.type": "LOCAL",
        "mlflow.source.name": f"socnav-wm {stage}",
    }
    if commit != "unknown":
        tags["mlflow.source.git.commit"] = commit
    if os.environ.get("DVC_EXP_NAME"):
        tags["dvc_exp_name"] = os.environ["DVC_EXP_NAME"]
    tags.update(machine_tags())
    parent = _PARENT.get()
    if parent is not None:
        tags["mlflow.parentRunId"] = parent[0]
        tags.update(parent[1])
    # No user name in containers without an /etc/passwd entry: leave the tag out.
    with contextlib.suppress(KeyError, OSError):
        tags["mlflow.user"] = getpass.getuser()
    mlflow_run = client.create_run(experiment_id, tags=tags, run_name=run_name or stage)
    run = _MlflowRun(client, mlflow_run.info.run_id)

    try:
        run.log_params(params)
        run.log_text(json.dumps(params, indent=2, sort_keys=True, default=str), "params.json")
        yield run
        run.flush()
    except BaseException as exc:
        status = "KILLED" if isinstance(exc, KeyboardInterrupt) else "FAILED"
        # Record what we can, but never let a tracking problem hide the stage's own exception.
        try:
            run.flush()
            run.set_tag("error", " ".join(f"{type(exc).__name__}: {exc}".split()))
            client.set_terminated(run.run_id, status=status)
        except Exception as tracking_exc:  # noqa: BLE001
            log.warning("could not mark MLflow run %s %s: %s", run.run_id, status, tracking_exc)
        raise
    client.set_terminated(run.run_id, status="FINISHED")


def _cpu_model() -> str:
    """The CPU's model name (Linux: /proc/cpuinfo), else what the platform module says."""
    import platform

    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine() or "unknown"


def machine_tags() -> dict[str, str]:
    """What a bit-for-bit rerun needs to match: the CPU model, the PyTorch build (with its
    BLAS/MKL and OpenMP) and the thread count of this process."""
    import sys

    tags = {"machine.cpu": _cpu_model(), "machine.cores": str(os.cpu_count() or 0)}
    torch = sys.modules.get("torch")  # only if the stage uses it: never imported here
    if torch is not None:
        tags["machine.torch"] = torch.__version__
        tags["machine.torch_threads"] = str(torch.get_num_threads())
        with contextlib.suppress(Exception):
            config = torch.__config__.show()
            found = re.search(r"BLAS_INFO=(\w+)", config)
            tags["machine.torch_blas"] = found.group(1) if found else "unknown"
            tags["machine.torch_parallel"] = torch.__config__.parallel_info().splitlines()[-1]
    return tags


def _experiment_id(client: Any, uri: str) -> str:
    from mlflow.exceptions import MlflowException

    name = experiment_name()
    experiment = client.get_experiment_by_name(name)
    if experiment is None:
        # A parallel stage (`dvc exp run`) may create it in between: then it is found below.
        with contextlib.suppress(MlflowException):
            client.create_experiment(
                name,
                artifact_location=_artifact_location(uri),
                # MLflow 3 opens an experiment of this kind in its model-training view.
                tags={
                    EXPERIMENT_KIND_TAG: EXPERIMENT_KIND,
                    DESCRIPTION_TAG: EXPERIMENT_DESCRIPTION,
                },
            )
        experiment = client.get_experiment_by_name(name)
        if experiment is None:
            raise TrackingError(f"{_redact(uri)}: cannot create the experiment {name!r}; {_HINT}")
    else:
        for key, value in ((EXPERIMENT_KIND_TAG, EXPERIMENT_KIND),
                           (DESCRIPTION_TAG, EXPERIMENT_DESCRIPTION)):  # fmt: skip
            if key not in experiment.tags:  # an older store's experiment
                client.set_experiment_tag(experiment.experiment_id, key, value)
    _check_artifact_store(uri, experiment.artifact_location)
    return experiment.experiment_id


def _check_artifact_store(uri: str, location: str | None) -> None:
    """The experiment's artifact folder must be writable (for local stores), checked before
    the run opens: otherwise the stage would do all its work and die logging its first file."""
    if not location or urllib.parse.urlsplit(location).scheme.lower() not in ("", "file"):
        return  # a server or an object store checks its own permissions
    _check_directory(f"{_redact(uri)} (artifact store {location})", _file_uri_path(location))


def _artifact_location(uri: str) -> str | None:
    """For SQLite, artifacts go to ``mlruns/<experiment>/`` beside the database.

    MLflow's own default is ``./mlruns`` in whatever directory the first run happened to start.
    """
    if not uri.lower().startswith("sqlite:///"):
        return None  # a server or another store has its own default
    database = uri[len("sqlite:///") :].split("?", 1)[0]
    if database in ("", ":memory:"):
        return None
    folder = re.sub(r"[^\w.-]+", "_", experiment_name())
    return (Path(database).resolve().parent / "mlruns" / folder).as_uri()


def _quiet_database_logs() -> None:
    # Creating or migrating the SQLite schema prints a page of alembic INFO lines.
    for name in ("alembic", "mlflow.store.db.utils"):
        logging.getLogger(name).setLevel(logging.WARNING)


def _git_commit() -> str:
    try:
        result = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, check=False
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    commit = result.stdout.strip()
    return commit if result.returncode == 0 and commit else "unknown"


def _param_value(value: Any) -> str:
    text = value if isinstance(value, str) else json.dumps(value, default=str)
    return _truncate(text, _MAX_PARAM_VALUE)


def _truncate(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."
