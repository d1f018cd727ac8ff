"""Typed configuration of every stage, as frozen dataclasses, and the named presets.

Each stage's module reads its own dataclass; run folders store them as JSON (`dataclasses.asdict`),
so a checkpoint rebuilds itself. `PipelineConfig` composes the stages of `windowshop video` and of
a service job. A knob is one field here: its CLI flag, its `--set KEY=VALUE` / API key and its
environment variable are derived from the field (windowshop/overrides.py), with the field's
trailing comment as its help text.
"""

from __future__ import annotations

from dataclasses import dataclass, field

# bytes of working memory one chunk of rays may take while training, evaluating or rendering
# (windowshop/memory.py): with the interpreter and torch (~0.5 GB) a 100x100 job stays under 2 GB
MEMORY_BUDGET = 512 * 2**20


@dataclass(frozen=True)
class SceneOptions:
    """How a posed-image source is loaded (every reader honours all of these)."""

    downscale: float = 1.0  # divide the stored resolution by this factor
    max_side: int | None = None  # or: resize so the longer side is at most this many pixels
    views: int | None = None  # keep N training views spread evenly around the object
    test_views: int | None = None  # keep K evenly spaced held-out views
    # few-view protocols: the 8 views of RegNeRF/FreeNeRF/DietNeRF on Blender are 26,86,2,55,75,93,16,73
    view_ids: tuple[int, ...] | None = None  # train on exactly these views (indices in the train split)
    test_every: int | None = None  # keep every k-th held-out view, from the first (the protocol's 8)
    background: str = "white"  # for sources with alpha: "white", "black" or "alpha" (kept)
    normalize: bool = True  # centre, up = +z, object box scaled into [-1, 1]^3


@dataclass(frozen=True)
class NerfConfig:
    """The NeRF of Mildenhall et al. 2020: encoding, MLP, samples per ray and learning rate.

    `near`/`far` are in the scene's normalised units; None uses the scene's own interval (our scenes
    are normalised, so the seed's "near 2, far 6 on lego" is whatever interval bounds the object).
    """

    freqs: int = 10  # L: frequencies of the position encoding (the identity is always included)
    freqs_dir: int = 4  # L_dir: frequencies of the direction encoding
    view_dependent: bool = True  # False: colour depends on position only
    encoding_pi: bool = False  # True: sin(2^k pi p) as the paper's formula; False: sin(2^k p), its code
    depth: int = 8  # D: layers of the trunk
    width: int = 256  # W: their width
    skip: int = 5  # the encoded input is concatenated again after this many layers (0: never)
    density_activation: str = "relu"  # the paper's; "softplus" never stops the gradient (no dead start)
    n_coarse: int = 64  # N_c: stratified samples per ray
    n_fine: int = 128  # N_f: inverse-CDF samples per ray for a separate fine network (0: one network)
    near: float | None = None  # where rays start, normalised units (None: the scene's)
    far: float | None = None  # where rays end, normalised units (None: the scene's)
    lr: float = 5e-4  # Adam's initial learning rate ...
    lr_final: float = 5e-5  # ... decayed exponentially to this at the end of the budget


NERF_PRESETS = {
    "paper": NerfConfig(),
    "tiny": NerfConfig(freqs=6, view_dependent=False, n_coarse=64, n_fine=0),
}


@dataclass(frozen=True)
class FastConfig:
    """The fast grid model (windowshop.field.fast): a density grid and a feature grid over the
    object's box, read by trilinear interpolation; each ray's features are composited and a tiny
    MLP turns them and the view direction into its colour. Samples are marched only through
    occupied cells; the grids grow coarse to fine.
    Sizes are in voxels of the box, so they mean the same for any scene."""

    voxels: int | None = None  # voxels at the end of the growth; None: from the pixel size (below)
    voxel_pixels: float = 1.0  # ... so that a voxel is this many training pixels wide at the object
    max_voxels: int = 160**3  # ... but no more than this (memory and time)
    # ... nor than this many per training pixel: a grid with more unknowns than its photos
    # constrain learns haze where few of them look (kermit's 11 photos: 4.1M voxels -> 0.69M,
    # held-out PSNR 20.3 -> 21.7 dB and a render twice as fast); well-covered scenes never reach it
    max_voxels_per_pixel: float = 1.0
    # ... nor than the rays the run will train on over this, estimated at each growth point from
    # the step rate since the last: a grid with more unknowns than its budget's rays can train
    # learns slower than a coarser one (lego 400 in 60 s: 4.1M voxels 28.2 dB, 2M 29.6)
    rays_per_voxel: float = 4.0  # ... nor than the run's training rays over this (0: no limit)
    start_fraction: float = 0.125  # voxels at the start, as a fraction of the final count
    growth: tuple[float, ...] = (0.1, 0.2, 0.3)  # progress at which the grid grows (geometrically)
    features: int = 16  # channels of the feature grid (16 floats: one cache line per vertex)
    hidden: int = 64  # width of the colour MLP's one hidden layer
    mlp_bf16: bool = True  # run the MLP in bfloat16 where the hardware has it (CPU: AVX512-BF16)
    sh_degree: int = 2  # spherical harmonics of the view direction fed to it (-1: no view dependence)
    # A trilinear grid has no detail finer than a voxel, so a render step of 0.75 changes a frame
    # by under one 8-bit level (48-54 dB against 0.5) and marches 1.5x fewer samples. Training
    # near it gives a budget more steps (bench/RESULTS.md, "train as it renders"): None: 0.7, or
    # 0.5 with few photos, whose fits the steps do not limit
    step: float | None = None  # marching step when training, in voxels of the current grid ...
    render_step: float = 0.75  # ... and when rendering
    alpha_init: float = 1e-2  # opacity of one final-resolution step at initialisation
    # Learning rates: swept at the steps the budgets give (bench/RESULTS.md, "learning rates");
    # nothing gains on lego without losing on temple or lego_tiny
    lr_grid: float = 0.2  # Adam on both grids ...
    lr_mlp: float = 1e-2  # ... and on the MLP
    lr_final: float = 0.3  # learning rates decay exponentially to this factor ...
    # ... then anneal at the end: it pays on long runs (lego 400x400 in 300 s: +0.4 dB) where a
    # lower lr_final all along loses on short ones (bench/RESULTS.md, "anneal")
    lr_tail: float = 0.15  # over this last share of the budget (0: no anneal) ...
    lr_tail_factor: float = 0.1  # ... the rates fall by this factor more, exponentially
    occupancy_warmup: int = 64  # steps before empty cells are first skipped
    occupancy_every: int = 16  # steps between refreshes of the occupancy grid
    occupancy_alpha: float = 2e-2  # cells with no corner this opaque (per final step) are skipped
    # Under 1/255, what a ray leaves behind can move no pixel by an 8-bit level (3e-3 against
    # 1e-3: -17% render time, same PSNR). Training at the same threshold spends no reads and
    # gradients on samples no frame shows: None: 3e-3, or 1e-4 with few photos, whose shape
    # the faint samples' colour still helps (8 views -0.3 dB at 3e-3)
    weight_threshold: float | None = None  # samples below this compositing weight get no colour ...
    render_threshold: float = 3e-3  # ... and when rendering, where rays also stop at this transmittance
    carve: bool = True  # masked scenes: never occupy space outside the visual hull of the masks
    # Few-photo priors (issue 17; bench/RESULTS.md measures each): a setting left at None is chosen
    # by the number of training photos, on at or under `few_views`, off above it.
    few_views: int = 20
    # mip-NeRF 360's distortion loss (concentrates each ray's weight): None: 0.01 with few photos
    distortion: float | None = None
    # total variation of the feature grid where samples show (colour varies smoothly where few
    # photos pin it): None: 0.003 with few photos
    tv_features: float | None = None
    # total variation of the raw density at the samples, its changes measured over 1/128 of the
    # box's longest side at any grid resolution (a smooth shape where few photos pin it; 8 views
    # of 400x400 +1.0 dB in 120 s): None: 1e-4 with few photos
    tv_density: float | None = None
    # stop after this many passes over the training pixels (0: never): a fit on few small photos
    # fits them closer after that but renders other views worse (5 views of 100x100 lose 0.8 dB
    # from 40 to 245 passes): None: 50 with few photos
    max_passes: float | None = None
    # views composited over a known colour with their alpha mattes (Blender's RGBA) trained over
    # random colours and carved like masked scenes: None: yes
    masked: bool | None = None
    # ... for this share of the budget, the rest over the scene's own colour, the one it is judged
    # on: an anti-aliased edge pixel's partial cover is no single opacity along one ray, so random
    # colours cost the last decibels there once the shape is set (lego 25 photos of 100x100 +0.3,
    # 100 of 400x400 +0.5 against never masked): None: 1 (to the end) with few photos, whose
    # shape needs the random colours throughout, else 0.5
    masked_until: float | None = None
    # at the end of training, empty the space that no training ray reached with at least this
    # transmittance (0: keep it): behind every photo's surface the density is free, and what it
    # holds under a plate photographed from above shows as haze from below (8 views of 400x400
    # +0.4 dB at 0.1). Off, as real captures lose 0.1-0.2 dB where a photo between the training
    # ones sees into what they barely reached, and a capture from one side would turn hollow
    # from behind (bench/RESULTS.md, "Few photos, round five")
    empty_unseen: float = 0.0
    # RegNeRF's priors on patches of rays from random cameras with no photo (fit/virtual.py):
    depth_smoothness: float = 0.0  # neighbouring rays' surface depths agree
    virtual_entropy: float = 0.0  # each ray's opacity is 0 or 1
    virtual_patches: int = 16  # patches per step ...
    patch_size: int = 8  # ... of this many pixels square
    # FreeNeRF's occlusion penalty: density within `occlusion_reach` (scene units) of where each
    # training ray enters the box
    occlusion: float = 0.0
    occlusion_reach: float = 0.1
    density_dropout: float = 0.0  # share of samples whose density training drops at random


FAST_PRESETS = {
    "default": FastConfig(),
}


@dataclass(frozen=True)
class PrepareOptions:
    """Photos or a video -> a posed scene (`windowshop prepare`)."""

    max_side: int | None = 640  # working resolution: the longer side in pixels (None: as given)
    video_frames: int = 40  # frames sampled from a video
    intrinsics: tuple[float, float, float, float] | None = None  # known fx, fy, cx, cy (photo px)
    matcher: str = "auto"  # or exhaustive, sequential, retrieval (auto: by count and order)
    masks: bool = True  # foreground masks (by colour on a plain background, else segmented)
    even_exposure: bool = True  # take each photo's own exposure and white balance out of its colours
    matting: str = "grabcut"  # "grabcut" (built in) or "rembg" (needs rembg and its weights)
    overwrite: bool = False  # replace an earlier prepare's output folder
    seed: int = 0  # random seed of structure from motion
    verbose: bool = False  # pycolmap's own logging
    verify_seconds: float = 45.0  # seconds within which a hypothesis that maps again may start
    force: bool = False  # deliver the best hypothesis even when none passes its checks (unverified)


@dataclass(frozen=True)
class FitConfig:
    """How long and how a model is trained (the learning-rate schedule itself is the model's)."""

    iters: int | None = 3000  # stop after this many steps in total (None: no step limit)
    seconds: float | None = None  # or after this many seconds of training in total
    batch_rays: int | None = None  # rays per step, drawn from every training view (None: the model's)
    seed: int = 0  # random seed of the model's initialisation and the ray batches
    log_every: int = 50  # steps between lines of log.jsonl
    checkpoint_every: int = 1000  # steps between checkpoints (one is always written at the end)
    memory_budget: int = MEMORY_BUDGET  # bytes one chunk of rays may take (training steps, evaluation)
    # the final checkpoint keeps Adam's moments, so that --resume carries on where it stopped;
    # without them it is a third of the size (290 MB instead of 860 for a 4M-voxel real capture)
    # and is written and read in a third of the time (checkpoints of interrupted runs keep them)
    final_optimizer: bool = True
    # refine each held-out camera's pose against the model before scoring it (metrics.json's
    # psnr_refined): for cameras from structure-from-motion, whose small errors would otherwise
    # count against the model; `video` turns it on for the photos it prepares
    refine_held_out: bool = False


@dataclass(frozen=True)
class VideoOptions:
    """The turntable's camera path and encoding (`windowshop render`); lengths in normalised units."""

    frames: int = 120  # frames of one revolution (or of the whole path)
    fps: float = 30.0  # frames per second of the video
    width: int = 256  # pixels
    height: int = 256  # pixels
    path: str = "orbit"  # "orbit", "spiral" or a nerfstudio camera-path JSON file
    radius: float | None = None  # None: the distance at which the object fills 80% of the frame
    elevation: float | None = None  # degrees above the orbit plane; None: the training views' median
    start_angle: float = 0.0  # degrees of azimuth past the first training camera
    fov: float | None = None  # vertical, degrees; None: the photos' median, zoomed to frame the object
    spiral_amplitude: float = 15.0  # degrees the spiral swings above and below its elevation
    memory_budget: int = MEMORY_BUDGET  # bytes one chunk of rays may take (bounds memory at any size)
    full_turn: bool = False  # turn all the way round even when the photos cover under 300 degrees
    background: str = "white"  # "white", "black" or "transparent" (alpha: a .webm video, PNG images)


@dataclass(frozen=True)
class ExportOptions:
    """A run's object as a model file shops accept (`windowshop export`; `video` writes GLB and USDZ)."""

    triangles: int = 100_000  # at most this many triangles (Amazon takes up to 150k)
    # pixels a side of the baked base-colour texture at most: fewer (halved, to 256) where the
    # photos' pixels on the object are coarser (export.texture.bake_size); 0: vertex colours only
    texture: int = 2048
    size_cm: float | None = None  # scale the object to this real height (None: the scene's own units)
    # marching-cubes cells along the longest side of the object's box at most (a grid field's
    # lattice has 1.5 cells a voxel of its grid: export.mesh.lattice_resolution)
    resolution: int = 256
    level_views: int = 8  # training views whose silhouettes choose the surface's density level
    bake_views: int = 24  # training photos projected onto the mesh for its colour (0: the field's)
    settle: bool = True  # move the surface to where those photos agree (export/settle.py)
    tune: bool = True  # move the surface to match all the photos and their masks (export/tune.py)
    refine: bool = True  # fit the texture to all the photos by least squares (export/refine.py)
    keep_share: float = 0.05  # pieces under this share of the largest piece's area are dropped
    smooth: int = 3  # Taubin steps after the tune at most (0: none), till it is no rougher than before
    close_unseen: bool = True  # close the side no photo saw by a hull, in grey (export/unseen.py)
    cut_support: bool = True  # cut a contact shadow's slab, the base flat (export/support.py)
    roughness: float = 1.0  # of the PBR material (never metallic; 1: no highlight over the baked ones)


@dataclass(frozen=True)
class RunConfig:
    """`windowshop fit` and one run of a study: a model trained on a scene. Bare model settings
    (`voxel_pixels=2`) go into `model_settings`; the rest by name or dotted path (`fit.seconds`)."""

    model: str = "fast"  # registered model name (fast, nerf)
    preset: str | None = None  # named settings of the model (nerf: paper, tiny)
    # any field of the model's own config (FastConfig, NerfConfig), checked when the model is built
    model_settings: dict = field(default_factory=dict)
    scene: SceneOptions = field(default_factory=SceneOptions)
    fit: FitConfig = field(default_factory=FitConfig)


@dataclass(frozen=True)
class PipelineConfig:
    """Photos -> prepare -> fit -> render: `windowshop video` and every service job, with defaults
    chosen for speed on a CPU. Override keys are dotted (`fit.seconds`, `render.frames`)."""

    model: str = "fast"  # registered model name (fast, nerf)
    preset: str | None = None  # named settings of the model
    # any field of the model's own config (FastConfig, NerfConfig), checked when the model is built
    model_settings: dict = field(default_factory=dict)
    prepare: PrepareOptions = field(default_factory=PrepareOptions)
    scene: SceneOptions = field(default_factory=lambda: SceneOptions(max_side=320))
    # 30 s of training: the whole video in about a minute on a 2-core CPU (bench/bench_real.py;
    # beer_can reached the same in-mask PSNR at 25 s as at 60 s, kermit's 11 photos gain from 60 s)
    # Its run is rendered, not resumed: the final checkpoint leaves out the optimizer's state.
    fit: FitConfig = field(default_factory=lambda: FitConfig(iters=None, seconds=30.0, log_every=10,
                                                             checkpoint_every=10**9,
                                                             final_optimizer=False))
    render: VideoOptions = field(default_factory=lambda: VideoOptions(frames=60))
    # When prepare runs long, training is cut so that the video is out in about `deadline`.
    deadline: float | None = 60.0  # seconds for the whole job (none: train for all of fit.seconds)
    min_fit_seconds: float = 15.0  # ... but training is never cut to less than this
    models: bool = True  # also write the object as 3D models beside the video (<stem>.glb, .usdz)
    export: ExportOptions = field(default_factory=ExportOptions)


@dataclass(frozen=True)
class DemoOptions:
    """The built-in object the demo renders and trains on (`windowshop demo`)."""

    views: int = 40  # training views of the object
    test_views: int = 8  # held-out views fit measures
    image_size: int = 64  # pixels a side of every training view


@dataclass(frozen=True)
class DemoConfig:
    """`windowshop demo`: the object, the model, a short training budget, a small turntable.

    Time, not steps, so the demo takes under a minute on any CPU however fast the model's steps are
    there. (On the 2-core CPU the fast model's held-out PSNR is the same after 30 s as after 120 s,
    24.9 dB: what is left is the aliasing of the exact, point-sampled training images.)"""

    model: str = "fast"  # registered model name (fast, nerf)
    preset: str | None = None  # named settings of the model
    # any field of the model's own config (FastConfig, NerfConfig), checked when the model is built
    model_settings: dict = field(default_factory=dict)
    demo: DemoOptions = field(default_factory=DemoOptions)
    fit: FitConfig = field(default_factory=lambda: FitConfig(iters=None, seconds=30.0))
    render: VideoOptions = field(default_factory=lambda: VideoOptions(frames=60, width=128,
                                                                      height=128))
