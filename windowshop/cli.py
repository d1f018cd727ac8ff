"""The `windowshop` command: one short function per subcommand.

Heavy imports (torch, pycolmap, the service) happen inside each function so `--help` is instant.
Errors the user can fix are raised as `windowshop.errors.UserError` and printed without a traceback.
Each stage's flags are generated from its dataclass in windowshop/config.py (windowshop/overrides.py):
a new field there is a new flag, with its comment as the help and its default shown, never
repeated here.
"""

from __future__ import annotations

import argparse
import sys

from windowshop import config as cfg
from windowshop.errors import UserError
from windowshop.overrides import add_flags, apply_overrides, flag_values, parse_assignments

DEVICE_HELP = "cpu, cuda, cuda:1 (default: CUDA when present)"


def _overrides(args: argparse.Namespace) -> dict:
    """The generated flags the user gave, then `--set KEY=VALUE` items (which win), then `--size`."""
    overrides = {**flag_values(args), **parse_assignments(getattr(args, "set", None) or [])}
    if getattr(args, "size", None) is not None:
        from windowshop.video.paths import parse_size

        width, height = parse_size(args.size)
        overrides.update({"render.width": width, "render.height": height} if args.size_in_render
                         else {"width": width, "height": height})
    return overrides


def _add_size(p: argparse.ArgumentParser, nested: bool) -> None:
    p.add_argument("--size", default=None, metavar="N|WxH",
                   help="turntable size: N (square) or WxH pixels; sets width and height")
    p.set_defaults(size_in_render=nested)


def _add_set(p: argparse.ArgumentParser, example: str) -> None:
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help=f"any setting by name or dotted path, typed as its field, e.g. --set {example} "
                        "(repeat; see windowshop/config.py)")


def _model_flags(p: argparse.ArgumentParser) -> None:
    """Flags of every model's own settings (a name two models share appears once)."""
    from windowshop.model import MODELS, model_class

    seen: set[str] = set()
    for name in MODELS:
        config_type = model_class(name).config_type
        add_flags(p, config_type, f"{name} model (override the preset)", exclude=tuple(seen))
        seen |= {f for f in config_type.__dataclass_fields__}


def cmd_inspect(args: argparse.Namespace) -> None:
    from windowshop.scene.inspect import inspect_command

    options = apply_overrides(cfg.SceneOptions(), flag_values(args), "inspect")
    inspect_command(args.path, options, as_json=args.json, plot=args.plot)


def cmd_fit(args: argparse.Namespace) -> None:
    from windowshop.device import pick_device
    from windowshop.fit.command import fit_command, summary

    metrics = fit_command(args.scene, _overrides(args), args.out, args.resume, pick_device(args.device))
    print(summary(metrics))


def cmd_eval(args: argparse.Namespace) -> None:
    from windowshop.device import pick_device
    from windowshop.fit.command import eval_command, summary

    print(summary(eval_command(args.run, pick_device(args.device))))


def cmd_render(args: argparse.Namespace) -> None:
    from windowshop.device import pick_device
    from windowshop.video.turntable import default_outputs, render_command

    options = apply_overrides(cfg.VideoOptions(), _overrides(args), "render")
    outputs = default_outputs(args.out, gif=args.gif, webp=args.webp, depth=args.depth,
                              poster=args.poster, frames_dir=args.frames_dir,
                              frames_format=args.frames_format,
                              transparent=options.background == "transparent")
    render_command(args.run, options, outputs, pick_device(args.device))


def cmd_demo(args: argparse.Namespace) -> None:
    from windowshop.demo import demo_command
    from windowshop.device import pick_device
    from windowshop.model import apply_run_overrides

    config = apply_run_overrides(cfg.DemoConfig(), _overrides(args), "demo")
    demo_command(args.out, config, pick_device(args.device))


def cmd_study(args: argparse.Namespace) -> None:
    from windowshop.device import pick_device
    from windowshop.study.command import study_command

    if args.broker is not None:
        from windowshop.distributed.study import distributed_study

        if args.device is not None:
            raise UserError("--device: with --broker each worker picks its own (windowshop worker "
                            "--device)")
        distributed_study(args.broker, args.preset, args.grid, args.scene, args.out, args.iters,
                          args.seconds, args.set)
        return
    study_command(args.preset, args.grid, args.scene, args.out, args.iters, args.seconds, args.set,
                  pick_device(args.device), show_progress=not args.quiet)


def cmd_prepare(args: argparse.Namespace) -> None:
    from dataclasses import replace

    from windowshop.photos.prepare import check_intrinsics, prepare

    options = apply_overrides(cfg.PrepareOptions(), flag_values(args), "prepare")
    options = replace(options, max_side=options.max_side or None)  # 0: the photos' own size
    check_intrinsics(options.intrinsics)
    prepare(args.input, args.out, options)


def cmd_video(args: argparse.Namespace) -> None:
    from windowshop.device import pick_device
    from windowshop.model import apply_run_overrides
    from windowshop.pipeline import make_video

    config = apply_run_overrides(cfg.PipelineConfig(), _overrides(args), "video")
    make_video(args.input, args.out, config, work_dir=args.work, device=pick_device(args.device))


def cmd_export(args: argparse.Namespace) -> None:
    from windowshop.device import pick_device
    from windowshop.export.command import export_command

    options = apply_overrides(cfg.ExportOptions(), flag_values(args), "export")
    export_command(args.run, args.out, args.format, options, pick_device(args.device))


def cmd_serve(args: argparse.Namespace) -> None:
    from windowshop.service.app import serve
    from windowshop.service.settings import ServiceSettings

    flags = {"host": args.host, "port": args.port, "data_dir": args.data,
             "concurrency": args.concurrency, "device": args.device,
             "certfile": args.certfile, "keyfile": args.keyfile}
    settings = ServiceSettings(**{k: v for k, v in flags.items() if v is not None})
    if args.broker is None:
        serve(settings)
        return
    from windowshop.distributed.celery_app import ClusterSettings
    from windowshop.distributed.service import serve_cluster

    cluster = {"broker": args.broker, "db": args.db, "public_url": args.public_url}
    serve_cluster(settings, ClusterSettings(**{k: v for k, v in cluster.items() if v is not None}))


def cmd_worker(args: argparse.Namespace) -> None:
    from windowshop.distributed.celery_app import QUEUES, ClusterSettings
    from windowshop.distributed.tasks import run_worker

    queues = [q.strip() for q in args.queues.split(",") if q.strip()] if args.queues else None
    if queues is None:
        import torch

        queues = ["cpu", "gpu"] if torch.cuda.is_available() else ["cpu"]
    if unknown := sorted(set(queues) - set(QUEUES)):
        raise UserError(f"--queues: unknown queue(s) {', '.join(unknown)}; use cpu and/or gpu")
    run_worker(ClusterSettings(broker=args.broker), queues, args.concurrency, args.name, args.device)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="windowshop", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="more logging")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("inspect", help="summarise a posed scene (any supported format)")
    p.add_argument("path")
    p.add_argument("--json", action="store_true", help="print the machine-readable summary")
    p.add_argument("--plot", default=None, help="draw the cameras around the object into FILE.png")
    add_flags(p, cfg.SceneOptions, "scene loading")
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser("render", help="render a run's 360° turntable video")
    p.add_argument("run", help="run folder written by `windowshop fit`")
    p.add_argument("--out", required=True,
                   help="the video to write: .mp4 (H.264, plays in browsers) or .webm (VP9, keeps alpha)")
    add_flags(p, cfg.VideoOptions, "turntable")
    _add_size(p, nested=False)
    for name, what in [("gif", "an animated GIF"), ("webp", "an animated WebP"),
                       ("depth", "a colour-mapped depth MP4"),
                       ("poster", "the frame facing most photos")]:
        p.add_argument(f"--{name}", nargs="?", const=True, default=False, metavar="FILE",
                       help=f"also write {what} (default name beside --out)")
    p.add_argument("--frames-dir", help="also write every frame as an image into DIR")
    p.add_argument("--frames-format", choices=["png", "jpg"], default="png")
    p.add_argument("--device", default=None, help=DEVICE_HELP)
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("demo", help="fit the built-in object and render its turntable (about a minute, CPU)")
    p.add_argument("--out", required=True, help="folder for run/, turntable.mp4, its poster, demo.json")
    add_flags(p, cfg.DemoConfig, "demo", exclude=("model_settings",))
    _add_size(p, nested=True)
    _add_set(p, "voxel_pixels=2")
    p.add_argument("--device", default=None, help=DEVICE_HELP)
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("fit", help="train a model on a posed scene into a run folder")
    p.add_argument("scene", nargs="?", help="posed scene (optional with --resume)")
    p.add_argument("--out", default=None, help="run folder to write")
    p.add_argument("--resume", default=None, metavar="RUN", help="carry on training this run folder")
    p.add_argument("--device", default=None, help=DEVICE_HELP)
    add_flags(p, cfg.RunConfig, "fit", exclude=("model_settings",))
    _model_flags(p)
    _add_set(p, "voxel_pixels=2")
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("eval", help="measure a run on its held-out views; write eval/*.png")
    p.add_argument("run", help="run folder written by `windowshop fit`")
    p.add_argument("--device", default=None, help=DEVICE_HELP)
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("study", help="run a grid of fits (the seed's Table 1) into REPORT.md",
                       description="Each combination is a run folder under OUT/runs; a finished "
                                   "one is skipped, so running the same command again resumes.")
    grid = p.add_mutually_exclusive_group(required=True)
    grid.add_argument("--preset", help="seed (the seed's Table 1) or nerf-ablation (NeRF's Table 4)")
    grid.add_argument("--grid", help="a YAML or JSON grid file of fit switches (see docs/study.md)")
    p.add_argument("--scene", required=True, help="posed scene every combination trains on")
    p.add_argument("--out", required=True, help="study folder: runs/, results.csv, REPORT.md")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--iters", type=int, default=None, help="every run's steps (not the grid's)")
    budget.add_argument("--seconds", type=float, default=None, help="or every run's training seconds")
    _add_set(p, "batch_rays=1024 or --set test_views=2")
    p.add_argument("--device", default=None, help=DEVICE_HELP)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--broker", default=None, metavar="URL", help="run the combinations on the "
                   "workers of this Redis broker (redis://HOST:6379/0, docs/scaling.md)")
    p.set_defaults(func=cmd_study)

    p = sub.add_parser("prepare", help="photos (folder or zip) or a video -> a posed scene folder")
    p.add_argument("input", help="a folder or zip of photos (JPEG, PNG, WebP, HEIC) or a video")
    p.add_argument("--out", required=True, help="new folder: transforms.json, images/, masks/, report")
    add_flags(p, cfg.PrepareOptions, "prepare")
    p.set_defaults(func=cmd_prepare)

    p = sub.add_parser("video", help="photos, a video or a posed scene -> a 360° turntable MP4",
                       description="Chains prepare (skipped for a posed scene), fit and render with "
                                   "defaults chosen for speed, printing each stage and its time. "
                                   "A setting two stages share is named by its stage: "
                                   "--prepare.max-side, --scene.max-side.")
    p.add_argument("input", help="a folder or zip of photos, a video, or a posed scene")
    p.add_argument("--out", required=True, help="the MP4 to write (a poster JPEG goes beside it)")
    p.add_argument("--work", default=None, help="folder for the posed scene and the run "
                                                "(default: <out>_work beside the MP4)")
    add_flags(p, cfg.PipelineConfig, "video", exclude=("model_settings",))
    _add_size(p, nested=True)
    _add_set(p, "voxel_pixels=2")
    p.add_argument("--device", default=None, help=DEVICE_HELP)
    p.set_defaults(func=cmd_video)

    p = sub.add_parser("export", help="a run's object as a 3D model: GLB, USDZ (AR) or PLY",
                       description="The object's surface from the field (only the object, +Y up, "
                                   "standing at the origin), decimated, with a baked base-colour "
                                   "texture; FILE.json beside it holds the matrix from the "
                                   "model's coordinates to the scene's source frame.")
    p.add_argument("run", help="run folder written by `windowshop fit` (or `video`'s work/run)")
    p.add_argument("--out", required=True, help="the file to write: .glb, .usdz or .ply")
    p.add_argument("--format", choices=["glb", "usdz", "ply"], default=None,
                   help="the file's format (default: from --out's extension)")
    add_flags(p, cfg.ExportOptions, "export")
    p.add_argument("--device", default=None, help=DEVICE_HELP)
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("serve", help="the web service and page: upload photos, get a 360° video",
                       description="Flags override the WINDOWSHOP_* environment variables; every "
                                   "other setting (limits, job speed) is one of those: see "
                                   "windowshop/service/settings.py.")
    p.add_argument("--host", default=None, help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="default 8000")
    p.add_argument("--data", default=None, help="folder of the job store and the jobs' files "
                                                "(default ./windowshop-data)")
    p.add_argument("--concurrency", type=int, default=None, help="jobs run at once (default 1)")
    p.add_argument("--device", default=None, help="the jobs' device: cpu, cuda (default: CUDA if present)")
    p.add_argument("--certfile", default=None, metavar="PEM", help="serve HTTPS with this "
                   "certificate (a phone's browser opens the camera only over HTTPS or on "
                   "localhost; docs/capture.md)")
    p.add_argument("--keyfile", default=None, metavar="PEM", help="the certificate's private key")
    p.add_argument("--broker", default=None, metavar="URL", help="send jobs to the workers of this "
                   "Redis broker (redis://HOST:6379/0) instead of the local worker (docs/scaling.md)")
    p.add_argument("--db", default=None, metavar="URL", help="with --broker: the job store's "
                   "SQLAlchemy URL, e.g. postgresql://... (default: SQLite in --data)")
    p.add_argument("--public-url", default=None, help="with --broker: how workers reach this "
                   "service (default http://HOST:PORT)")
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser("worker", help="run jobs and study runs sent through a Redis broker",
                       description="A Celery worker; it needs the broker and the service's address "
                                   "(sent with every job), no shared disk. See docs/scaling.md.")
    p.add_argument("--broker", required=True, metavar="URL", help="redis://HOST:6379/0")
    p.add_argument("--queues", default=None, help="cpu, gpu or cpu,gpu (default: cpu,gpu with "
                                                  "CUDA, else cpu)")
    p.add_argument("--concurrency", type=int, default=1, help="tasks run at once (processes)")
    p.add_argument("--name", default=None, help="worker name, e.g. gpu1@%%h (default celery@HOST)")
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA if present)")
    p.set_defaults(func=cmd_worker)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except UserError as err:
        print(f"windowshop {args.command}: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
