"""`windowshop study --broker`: a study's combinations run by the Celery workers, gathered here.

The study command (the client) packs the scene once, sends every unfinished combination as a
`windowshop.study_run` task (on `gpu` when a worker consumes it, else `cpu`) and waits. A worker
unpacks the scene into a temporary folder, runs `run_combination` there, points the run's records
at the client's scene path (so `windowshop eval` and `render` work on the gathered folder), and
returns the run folder zipped, with the study's truth view, through Celery's result backend (the
same Redis). The client unpacks each into OUT/runs/<NN-name>/ exactly as a local run leaves it, so
resume (finished rows are skipped without sending anything) and `write_report` are the local ones.

The scene and each run folder travel inside Redis (the task message, the result), base64 in JSON:
meant for scenes and run folders of tens of MB, not GB (`MAX_SCENE_BYTES`).
"""

from __future__ import annotations

import base64
import dataclasses
import io
import json
import shlex
import socket
import tempfile
import time
import zipfile
from pathlib import Path

from windowshop.distributed.celery_app import ClusterSettings, app, configure, gpu_workers
from windowshop.distributed.transfer import replace_folder, unzip_to, zip_folder
from windowshop.errors import UserError

MAX_SCENE_BYTES = 64 * 2**20  # every task message carries the scene: keep Redis' memory sane
WORKER = "worker"  # extra key of study_row.json: the Celery worker that ran the combination


def _encode(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def pack_scene(scene: Path) -> tuple[bytes, str]:
    """(a zip of what the scene at `scene` needs, the scene's path inside it).

    A .npz is self-contained; any other file (transforms.json, a *_par.txt, ...) names images
    beside it, so its folder travels; a folder travels whole.
    """
    root = scene if scene.is_dir() or scene.suffix.lower() == ".npz" else scene.parent
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
        for path in files:
            archive.write(path, path.relative_to(root.parent).as_posix())
    return buffer.getvalue(), scene.relative_to(root.parent).as_posix()


@app.task(bind=True, name="windowshop.study_run", ignore_result=False)
def study_run(self, combo: dict, scene_zip: str, scene_name: str, scene_source: str) -> dict:
    """Run one combination on this worker; {"row", "worker", "run" (zip, base64), "truth"}.

    A failure comes back as {"error": message} so the client can name the combination.
    """
    from windowshop.device import pick_device
    from windowshop.distributed.tasks import _DEVICE
    from windowshop.study.grids import Combination
    from windowshop.study.runner import TRUTH, run_combination

    worker = self.request.hostname or socket.gethostname()
    combination = Combination(**combo)
    try:
        with tempfile.TemporaryDirectory(prefix="windowshop-study-") as tmp:
            tmp = Path(tmp)
            (tmp / "scene.zip").write_bytes(base64.b64decode(scene_zip))
            unzip_to(tmp / "scene.zip", tmp / "scene")
            study_dir = tmp / "study"
            row = run_combination(combination, tmp / "scene" / scene_name, study_dir,
                                  pick_device(_DEVICE["device"]))
            run_dir = study_dir / "runs" / combination.folder
            _relocate(run_dir, scene_source)
            truth = study_dir / TRUTH
            return {"row": dataclasses.asdict(row), "worker": worker,
                    "run": _encode(zip_folder(run_dir, tmp / "run.zip").read_bytes()),
                    "truth": _encode(truth.read_bytes()) if truth.is_file() else None}
    except Exception as err:  # noqa: BLE001 - reported to the client, which names the combination
        kind = "" if isinstance(err, UserError) else f"{type(err).__name__}: "
        return {"error": f"{kind}{err}", "worker": worker}


def _relocate(run_dir: Path, source: str) -> None:
    """Record `source` (the client's scene) as the run's scene in config.json and the checkpoint."""
    import torch

    from windowshop.fit.checkpoint import CHECKPOINT, CONFIG

    config = json.loads((run_dir / CONFIG).read_text())
    config["scene"]["source"] = source
    (run_dir / CONFIG).write_text(json.dumps(config, indent=2) + "\n")
    state = torch.load(run_dir / CHECKPOINT, map_location="cpu", weights_only=True)
    state["scene"]["source"] = source
    torch.save(state, run_dir / CHECKPOINT)


def _queue(celery) -> str:
    """`gpu` when a worker consumes it, else `cpu` (as the service routes training)."""
    replies = celery.control.inspect(timeout=1.0).active_queues()
    if not replies:
        print("study: no worker answered; the runs wait in the queue until one starts", flush=True)
    return "gpu" if gpu_workers(replies) else "cpu"


def _install(out: Path, combo, result: dict) -> None:
    """Unpack a worker's run folder into OUT/runs/<folder> (and the truth view, once)."""
    from windowshop.study.runner import ROW, RUNS, TRUTH

    run_dir = out / RUNS / combo.folder
    with tempfile.TemporaryDirectory(dir=out) as tmp:
        archive = Path(tmp) / "run.zip"
        archive.write_bytes(base64.b64decode(result["run"]))
        new = unzip_to(archive, Path(tmp) / "run")
        row = json.loads((new / ROW).read_text())
        (new / ROW).write_text(json.dumps({**row, WORKER: result["worker"]}, indent=2) + "\n")
        run_dir.parent.mkdir(parents=True, exist_ok=True)
        replace_folder(new, run_dir)
    if result["truth"] and not (out / TRUTH).is_file():
        (out / TRUTH).write_bytes(base64.b64decode(result["truth"]))


def _gather(pending: dict, out: Path, skipped: int, total: int,
            poll: float = 0.5) -> tuple[dict, list[str]]:
    """Wait for every task of `pending` ({AsyncResult: combo}); (rows by index, errors)."""
    from windowshop.study.runner import ResultRow, row_summary

    rows, errors = {}, []
    while pending:
        for result in [r for r in pending if r.ready()]:
            combo, answer = pending.pop(result), result.get(propagate=False)
            if not isinstance(answer, dict) or "error" in answer:
                reason = answer.get("error") if isinstance(answer, dict) else repr(answer)
                errors.append(f"combination {combo.folder}: {reason}")
                continue
            _install(out, combo, answer)
            rows[combo.index] = ResultRow(**answer["row"])
            print(f"study: {skipped + len(rows)}/{total} {row_summary(rows[combo.index])} "
                  f"on {answer['worker']}", flush=True)
        time.sleep(poll if pending else 0)
    return rows, errors


def _write_study_json(out: Path, grid, info) -> None:
    from windowshop.study.runner import STUDY

    out.mkdir(parents=True, exist_ok=True)  # as run_study writes it
    (out / STUDY).write_text(json.dumps({"info": dataclasses.asdict(info),
                                         "grid": dataclasses.asdict(grid)}, indent=2) + "\n")


def distributed_study(broker: str, preset: str | None, grid_file: str | None, scene: str, out: str,
                      iters: int | None, seconds: float | None, assignments: list[str]) -> list:
    """`windowshop study --broker`: run (or resume) a study on the workers; returns its rows."""
    from windowshop.overrides import parse_assignments
    from windowshop.study.command import command_line
    from windowshop.study.grids import budget_overrides, load_grid
    from windowshop.study.report import REPORT, write_report
    from windowshop.study.runner import resolve, run_combination, run_state, study_info

    overrides = {**parse_assignments(assignments), **budget_overrides(iters, seconds)}
    grid = load_grid(preset, grid_file, overrides)
    source = Path(scene).resolve()
    done = {}
    for combo in grid.combinations:  # every combination checked (and finished ones found) first
        spec = resolve(combo.settings, combo.folder)
        if run_state(Path(out) / "runs" / combo.folder, spec, str(source)) == "done":
            done[combo.index] = run_combination(combo, source, out, "cpu")  # "skipped": reads only
    command = command_line(preset, grid_file, scene, out, iters, seconds, assignments)
    info = dataclasses.replace(study_info(grid, scene, overrides, "cpu", command + " --broker "
                                          + shlex.quote(broker)),
                               machine=f"the Celery workers of {broker}", device="each worker's")
    out_dir = Path(out)
    _write_study_json(out_dir, grid, info)
    todo = [c for c in grid.combinations if c.index not in done]
    errors = []
    if todo:
        rows, errors = _send_and_gather(broker, todo, source, out_dir, len(done),
                                        len(grid.combinations))
        done.update(rows)
    rows = [done[c.index] for c in grid.combinations if c.index in done]
    if rows:
        write_report(out_dir, grid, rows, info)
        print(f"wrote {out_dir / REPORT}")
    if errors:
        raise UserError("; ".join(errors) + " (running the same study command again retries "
                        "only the unfinished combinations)")
    return rows


def _send_and_gather(broker: str, todo: list, source: Path, out: Path, skipped: int,
                     total: int) -> tuple[dict, list[str]]:
    """Send `todo` to the workers and gather them; Ctrl-C revokes what has not finished."""
    if not source.exists():
        raise UserError(f"{source}: no such scene file or folder")
    packed, name = pack_scene(source)
    if len(packed) > MAX_SCENE_BYTES:
        raise UserError(f"{source}: the scene packs to {len(packed) / 2**20:.0f} MB, more than the "
                        f"{MAX_SCENE_BYTES / 2**20:.0f} MB a distributed study sends in its task "
                        f"messages; run the study locally (without --broker) or downscale the scene")
    celery = configure(ClusterSettings(broker=broker))
    queue, payload = _queue(celery), _encode(packed)
    pending = {study_run.apply_async((dataclasses.asdict(c), payload, name, str(source)),
                                     queue=queue): c for c in todo}
    print(f"study: {len(todo)} combination(s) sent to the {queue} queue of {broker}"
          + (f" ({skipped} finished earlier, skipped)" if skipped else ""), flush=True)
    try:
        return _gather(pending, out, skipped, total)
    except KeyboardInterrupt:
        for result in pending:
            result.revoke(terminate=True, signal="SIGKILL")
        raise
