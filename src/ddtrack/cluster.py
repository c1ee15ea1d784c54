"""Where ``sweep`` and ``bench`` run: their cluster options, checked before anything runs, and the Dask client
of a running scheduler or of an embedded cluster on 127.0.0.1."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click

from .errors import ConfigError, RunError

CONNECT_TIMEOUT_S = 20  #: how long sweep and bench try to reach a running scheduler before exit 2 [s]


def cluster_options(command: Callable) -> Callable:
    """The options that choose where ``sweep`` and ``bench`` run.

    They are ``--scheduler``, ``--scheduler-file`` and ``--workers``.
    """
    options = [
        click.option("--scheduler", metavar="ADDRESS", help="Use a running Dask scheduler, e.g. tls://10.0.0.5:8786."),
        click.option(
            "--scheduler-file",
            type=click.Path(path_type=Path),
            metavar="FILE",
            help="Use the running Dask scheduler described by FILE (dask scheduler --scheduler-file).",
        ),
        click.option(
            "--workers",
            type=click.IntRange(min=1, max=1024),
            metavar="N",
            help="Worker processes of the embedded local cluster [default: CPU count].",
        ),
    ]
    for option in reversed(options):  # decorators apply bottom-up: keep the options in this order in --help
        command = option(command)
    return command


def check_cluster_options(scheduler: str | None, scheduler_file: Path | None, workers: int | None) -> None:
    """Reject contradictory cluster options of ``sweep`` and ``bench`` before anything runs (exit code 2)."""
    if scheduler is not None and scheduler_file is not None:
        raise ConfigError("--scheduler", "give --scheduler or --scheduler-file, not both")
    if workers is not None and (scheduler is not None or scheduler_file is not None):
        raise ConfigError(
            "--workers",
            "only applies to the embedded cluster",
            "start workers on the cluster with `dask worker` instead",
        )
    if scheduler_file is not None and not scheduler_file.is_file():
        raise ConfigError(
            "--scheduler-file",
            f"'{scheduler_file}' does not exist",
            "start the scheduler with `dask scheduler --scheduler-file FILE` first",
        )


@contextmanager
def dask_client(scheduler: str | None, scheduler_file: Path | None, workers: int | None) -> Iterator[object]:
    """A client of the given scheduler, or of an embedded cluster on 127.0.0.1 (closed on exit)."""
    from distributed import Client

    cluster = None
    try:
        if scheduler is not None or scheduler_file is not None:
            try:
                client = Client(
                    scheduler,
                    scheduler_file=None if scheduler_file is None else str(scheduler_file),
                    timeout=f"{CONNECT_TIMEOUT_S}s",
                )
            except (OSError, TimeoutError) as exc:
                raise RunError(f"cannot reach the Dask scheduler ({exc})") from None
        else:
            cluster = local_cluster(workers or os.cpu_count() or 1)
            client = Client(cluster)
        with client:
            yield client
    finally:
        if cluster is not None:
            cluster.close()


def local_cluster(workers: int) -> Any:
    """An embedded cluster that listens on loopback only, with one thread per worker process."""
    import logging

    from distributed import LocalCluster

    # the scheduler serves its HTTP endpoints whatever the dashboard setting (None still takes :8787, and warns when
    # another cluster holds it): a free port on loopback instead
    return LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
        silence_logs=logging.ERROR,
    )
