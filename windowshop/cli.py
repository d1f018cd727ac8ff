"""The `windowshop` command: one short function per subcommand.

Heavy imports (torch, pycolmap, the service) happen inside each function so `--help` is instant.
Errors the user can fix are raised as `windowshop.errors.UserError` and printed without a traceback.
"""

from __future__ import annotations

import argparse
import sys

from windowshop.errors import UserError


def _scene_options(args: argparse.Namespace):
    from windowshop.config import SceneOptions

    return SceneOptions(downscale=args.downscale, max_side=args.max_side, views=args.views,
                        test_views=args.test_views, background=args.background)


def _add_scene_flags(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scene loading")
    g.add_argument("--downscale", type=float, default=1.0, help="divide the resolution by K")
    g.add_argument("--max-side", type=int, default=None, help="resize so the longer side is at most N")
    g.add_argument("--views", type=int, default=None, help="keep N training views spread evenly")
    g.add_argument("--test-views", type=int, default=None, help="keep K evenly spaced test views")
    g.add_argument("--background", choices=["white", "black", "alpha"], default="white",
                   help="background for sources with alpha")


def cmd_inspect(args: argparse.Namespace) -> None:
    from windowshop.scene.inspect import inspect_command

    inspect_command(args.path, _scene_options(args), as_json=args.json, plot=args.plot)


DEFAULT_MODEL = "fast"  # the model `fit`, `demo` and `video` train unless --model says otherwise


def _add_fit_flags(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("training (defaults: windowshop.config.FitConfig)")
    budget = g.add_mutually_exclusive_group()
    budget.add_argument("--iters", type=int, default=None, help="train for N steps in total")
    budget.add_argument("--seconds", type=float, default=None, help="train for S seconds in total")
    g.add_argument("--batch-rays", type=int, default=None, help="rays per step")
    g.add_argument("--seed", type=int, default=None)
    g.add_argument("--log-every", type=int, default=None, help="steps between log.jsonl lines")
    g.add_argument("--checkpoint-every", type=int, default=None, help="steps between checkpoints")
    g.add_argument("--eval-chunk", type=int, default=None, help="rays rendered at once in evaluation")


def _add_nerf_flags(p: argparse.ArgumentParser) -> list[str]:
    """NeRF settings; each flag's dest is a NerfConfig field. Returns the dests."""
    g = p.add_argument_group("nerf model (override the preset)")
    flags = [("--freqs", int, "L: position encoding frequencies"),
             ("--freqs-dir", int, "L_dir: direction encoding frequencies"),
             ("--depth", int, "D: layers of the MLP"), ("--width", int, "W: width of the MLP"),
             ("--skip", int, "concatenate the input again after this many layers (0: never)"),
             ("--n-coarse", int, "N_c: stratified samples per ray"),
             ("--n-fine", int, "N_f: hierarchical samples for a fine network (0: none)"),
             ("--near", float, "near distance, normalised units (default: the scene's)"),
             ("--far", float, "far distance, normalised units (default: the scene's)"),
             ("--lr", float, "initial learning rate"), ("--lr-final", float, "final learning rate")]
    for flag, kind, text in flags:
        g.add_argument(flag, type=kind, default=None, help=text)
    g.add_argument("--view-dependent", action=argparse.BooleanOptionalAction, default=None,
                   help="colour depends on the viewing direction")
    g.add_argument("--encoding-pi", action=argparse.BooleanOptionalAction, default=None,
                   help="sin(2^k pi p) as the paper's formula instead of its code's sin(2^k p)")
    g.add_argument("--density-activation", choices=["relu", "softplus"], default=None,
                   help="relu as the paper; softplus cannot get stuck at zero density")
    return [f[0][2:].replace("-", "_") for f in flags] + ["view_dependent", "encoding_pi",
                                                          "density_activation"]


def cmd_fit(args: argparse.Namespace) -> None:
    from windowshop.device import pick_device
    from windowshop.fit.command import fit_command, summary
    from windowshop.study.grids import parse_assignments

    model_overrides = {k: getattr(args, k) for k in args.model_flags if getattr(args, k) is not None}
    model_overrides.update(parse_assignments(args.set))
    fit_overrides = {k: getattr(args, k) for k in ("iters", "seconds", "batch_rays", "seed",
                                                  "log_every", "checkpoint_every", "eval_chunk")}
    metrics = fit_command(args.scene, _scene_options(args), args.model, args.preset, model_overrides,
                          fit_overrides, args.out, args.resume, pick_device(args.device))
    print(summary(metrics))


def cmd_eval(args: argparse.Namespace) -> None:
    from windowshop.device import pick_device
    from windowshop.fit.command import eval_command, summary

    print(summary(eval_command(args.run, pick_device(args.device))))


def cmd_render(args: argparse.Namespace) -> None:
    from windowshop.config import VideoOptions
    from windowshop.device import pick_device
    from windowshop.video.paths import parse_size
    from windowshop.video.turntable import default_outputs, render_command

    width, height = parse_size(args.size)
    options = VideoOptions(frames=args.frames, fps=args.fps, width=width, height=height,
                           path=args.path, radius=args.radius, elevation=args.elevation,
                           start_angle=args.start_angle, fov=args.fov, chunk=args.chunk)
    outputs = default_outputs(args.out, gif=args.gif, webp=args.webp, depth=args.depth,
                              poster=args.poster, frames_dir=args.frames_dir,
                              frames_format=args.frames_format)
    render_command(args.run, options, outputs, pick_device(args.device))


def cmd_demo(args: argparse.Namespace) -> None:
    from windowshop.config import FitConfig
    from windowshop.demo import DEMO_SECONDS, DemoOptions, demo_command
    from windowshop.device import pick_device

    budget = {"iters": args.iters, "seconds": args.seconds or (None if args.iters else DEMO_SECONDS)}
    sizes = {"views": args.views, "image_size": args.image_size, "frames": args.frames,
             "video_size": args.size}
    options = DemoOptions(**{k: v for k, v in sizes.items() if v is not None})
    demo_command(args.out, args.model, args.preset, FitConfig(**budget), options,
                 pick_device(args.device))


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
    from windowshop.config import PrepareOptions
    from windowshop.photos.prepare import parse_intrinsics, prepare

    options = PrepareOptions(max_side=args.max_side or None, frames=args.frames,
                             intrinsics=parse_intrinsics(args.intrinsics), matcher=args.matcher,
                             masks=not args.no_masks, matting=args.matting,
                             overwrite=args.overwrite, verbose=args.verbose)
    prepare(args.input, args.out, options)


def cmd_video(args: argparse.Namespace) -> None:
    from dataclasses import replace

    from windowshop.device import pick_device
    from windowshop.pipeline import VideoSettings, make_video

    base = VideoSettings()
    budget = ({"train_seconds": None, "train_steps": args.iters} if args.iters else
              {"train_seconds": args.seconds or base.train_seconds})
    settings = replace(base, model=args.model, **budget, frames=args.frames, fps=args.fps,
                       frame_size=args.size,
                       prepare=replace(base.prepare, max_side=args.max_side or None,
                                       verbose=args.verbose))
    make_video(args.input, args.out, settings, work_dir=args.work, device=pick_device(args.device))


def cmd_serve(args: argparse.Namespace) -> None:
    from windowshop.service.app import serve
    from windowshop.service.settings import ServiceSettings

    flags = {"host": args.host, "port": args.port, "data_dir": args.data,
             "concurrency": args.concurrency, "device": args.device}
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
    _add_scene_flags(p)
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser("render", help="render a run's 360° turntable video")
    p.add_argument("run", help="run folder written by `windowshop fit`")
    p.add_argument("--out", required=True, help="the MP4 to write (H.264, plays in browsers)")
    p.add_argument("--frames", type=int, default=120, help="frames in one turn")
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--size", default="256", help="N (square) or WxH pixels")
    p.add_argument("--path", default="orbit",
                   help="orbit, spiral, or a nerfstudio camera-path JSON (which sets frames and size)")
    p.add_argument("--radius", type=float, help="orbit radius in normalised units (default: cameras')")
    p.add_argument("--elevation", type=float, help="degrees above the object (default: cameras')")
    p.add_argument("--start-angle", type=float, default=0.0,
                   help="degrees past the first training photo's direction")
    p.add_argument("--fov", type=float, help="vertical field of view, degrees (default: cameras')")
    for name, what in [("gif", "an animated GIF"), ("webp", "an animated WebP"),
                       ("depth", "a colour-mapped depth MP4"), ("poster", "the first frame")]:
        p.add_argument(f"--{name}", nargs="?", const=True, default=False, metavar="FILE",
                       help=f"also write {what} (default name beside --out)")
    p.add_argument("--frames-dir", help="also write every frame as an image into DIR")
    p.add_argument("--frames-format", choices=["png", "jpg"], default="png")
    p.add_argument("--chunk", type=int, default=8192, help="rays rendered at once (memory)")
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA if present)")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("demo", help="fit the built-in object and render its turntable (minutes, CPU)")
    p.add_argument("--out", required=True, help="folder for run/, turntable.mp4, its poster, demo.json")
    p.add_argument("--model", default=DEFAULT_MODEL, help="registered model name (nerf, fast)")
    p.add_argument("--preset", default=None, help="named settings of the model")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--iters", type=int, default=None, help="training steps")
    budget.add_argument("--seconds", type=float, default=None,
                        help="or seconds of training (default: 30)")
    p.add_argument("--views", type=int, help="training views of the object (default: 40)")
    p.add_argument("--image-size", type=int, help="pixels a side of the training views (default: 64)")
    p.add_argument("--frames", type=int, help="turntable frames (default: 60)")
    p.add_argument("--size", type=int, help="pixels a side of the turntable (default: 128)")
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA if present)")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("fit", help="train a model on a posed scene into a run folder")
    p.add_argument("scene", nargs="?", help="posed scene (optional with --resume)")
    p.add_argument("--model", default=DEFAULT_MODEL, help="registered model name (nerf, fast)")
    p.add_argument("--preset", default=None, help="named settings of the model (nerf: paper, tiny)")
    p.add_argument("--out", default=None, help="run folder to write")
    p.add_argument("--resume", default=None, metavar="RUN", help="carry on training this run folder")
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA when present)")
    _add_scene_flags(p)
    _add_fit_flags(p)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="any setting of the model's config, e.g. --set voxel_pixels=2 (fast: "
                        "windowshop.config.FastConfig)")
    p.set_defaults(func=cmd_fit, model_flags=_add_nerf_flags(p))

    p = sub.add_parser("eval", help="measure a run on its held-out views; write eval/*.png")
    p.add_argument("run", help="run folder written by `windowshop fit`")
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA when present)")
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
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a fit switch for every run, e.g. batch_rays=1024 or test_views=2 (repeat)")
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA when present)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--broker", default=None, metavar="URL", help="run the combinations on the "
                   "workers of this Redis broker (redis://HOST:6379/0, docs/scaling.md)")
    p.set_defaults(func=cmd_study)

    p = sub.add_parser("prepare", help="photos (folder or zip) or a video -> a posed scene folder")
    p.add_argument("input", help="a folder or zip of photos (JPEG, PNG, WebP, HEIC) or a video")
    p.add_argument("--out", required=True, help="new folder: transforms.json, images/, masks/, report")
    p.add_argument("--max-side", type=int, default=640,
                   help="working resolution: longer side in pixels (0: keep the photos' size)")
    p.add_argument("--frames", type=int, default=40, help="frames sampled from a video")
    p.add_argument("--intrinsics", default=None, metavar="FX,FY,CX,CY",
                   help="known camera intrinsics in pixels of the photos (kept fixed)")
    p.add_argument("--matcher", choices=["auto", "exhaustive", "sequential"], default="auto",
                   help="feature matching (auto: sequential for a video, else exhaustive)")
    p.add_argument("--no-masks", action="store_true",
                   help="no foreground masks (the model then learns the whole photos)")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier prepare in --out")
    p.add_argument("--matting", choices=["grabcut", "rembg"], default="grabcut", help="grabcut, or rembg if installed")
    p.set_defaults(func=cmd_prepare)

    p = sub.add_parser("video", help="photos, a video or a posed scene -> a 360° turntable MP4",
                       description="Chains prepare (skipped for a posed scene), fit and render with "
                                   "defaults chosen for speed, printing each stage and its time.")
    p.add_argument("input", help="a folder or zip of photos, a video, or a posed scene")
    p.add_argument("--out", required=True, help="the MP4 to write (a poster JPEG goes beside it)")
    p.add_argument("--work", default=None, help="folder for the posed scene and the run "
                                                "(default: <out>_work beside the MP4)")
    p.add_argument("--model", default="fast", help="registered model name (fast, nerf)")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--seconds", type=float, default=None, help="training seconds (default 60)")
    budget.add_argument("--iters", type=int, default=None, help="or training steps")
    p.add_argument("--max-side", type=int, default=640,
                   help="working resolution of the photos (0: keep their size)")
    p.add_argument("--frames", type=int, default=60, help="turntable frames")
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--size", type=int, default=256, help="pixels a side of the turntable")
    p.add_argument("--device", default=None, help="cpu, cuda, cuda:1 (default: CUDA if present)")
    p.set_defaults(func=cmd_video)

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
