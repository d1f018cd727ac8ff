"""Distributed mode: jobs and studies run by Celery workers on many machines through a Redis broker.

    windowshop serve --broker redis://HOST:6379/0 [--db postgresql://...]   the web service
    windowshop worker --broker redis://HOST:6379/0 [--queues cpu,gpu]       on every machine

The single-machine service (windowshop.service) is unchanged; this package puts a shared SQL job
store (store.py), the Celery application (celery_app.py), the worker's tasks (tasks.py) and the
service's side of it (service.py: dispatch, and the worker-facing routes inputs and results travel
through) beside it, and `windowshop study --broker` (study.py: a study's runs as
tasks, gathered by the command). See docs/scaling.md.
"""
