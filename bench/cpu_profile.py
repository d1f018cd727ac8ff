"""Run a command as it would run on an ordinary CPU: AVX2 and FMA only, no bfloat16.

    python bench/cpu_profile.py ordinary python bench/bench_real.py --photos 20
    python bench/cpu_profile.py host python bench/bench_real.py --photos 20

Most sellers' laptops (and a 2-core AMD Zen 3 cloud machine) have AVX2 and no AVX-512 or
AVX512-BF16, which this project's machine has: there PyTorch's kernels use AVX-512, oneDNN runs
the fast model's MLP in bfloat16 (about 3x) and the fused kernels are built with -march=native.
"ordinary" lowers all three through their own switches (PyTorch's ATEN_CPU_CAPABILITY,
oneDNN's ONEDNN_MAX_CPU_ISA, the kernels' WINDOWSHOP_KERNELS_MARCH=x86-64-v3), which must be
set before the process starts, hence this wrapper. Every bench row records the profile it ran
under (provenance.machine()'s "cpu").
"""

from __future__ import annotations

import os
import sys

PROFILES = {
    "ordinary": {"ATEN_CPU_CAPABILITY": "avx2", "ONEDNN_MAX_CPU_ISA": "AVX2",
                 "WINDOWSHOP_KERNELS_MARCH": "x86-64-v3"},
    "host": {},
}


def main() -> None:
    if len(sys.argv) < 3 or sys.argv[1] not in PROFILES:
        sys.exit(f"usage: {sys.argv[0]} {{{','.join(PROFILES)}}} COMMAND [ARGS...]")
    env = {k: v for k, v in os.environ.items() if k not in PROFILES["ordinary"]}
    env.update(PROFILES[sys.argv[1]], WINDOWSHOP_CPU_PROFILE=sys.argv[1])
    os.execvpe(sys.argv[2], sys.argv[2:], env)


if __name__ == "__main__":
    main()
