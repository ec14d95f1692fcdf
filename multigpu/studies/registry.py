"""The names of the experiments and benchmarks, with where each lives: the command line's help
and dispatch read them here without importing the studies themselves (they pull in matplotlib,
the scenes and the MPI launcher: half a second at every start)."""

from __future__ import annotations

import importlib

#: ``multigpu experiment NAME``: name -> "module:function" in ``multigpu.studies``
EXPERIMENTS = {
    "gpus": "paper:exp_gpus", "resolution": "paper:exp_resolution", "balance": "paper:exp_balance",
    "strips": "paper:exp_strips", "orbit": "paper:exp_orbit", "overlap": "beyond:exp_overlap",
    "cost": "beyond:exp_cost", "speedup": "beyond:exp_speedup", "partition": "beyond:exp_partition",
    "compare": "compare:exp_compare", "payoff": "payoff:exp_payoff", "walls": "walls:exp_walls",
    "hybrid": "walls:exp_hybrid", "sixteen": "walls:exp_sixteen", "fidelity": "fidelity:exp_fidelity",
    "stereo": "stereo_bench:exp_stereo",
}

#: ``multigpu bench NAME``: name -> ("module:function" taking ``quick``, or None where the
#: command line passes more arguments itself, what it measures)
BENCHES = {
    "balance": ("bench:bench_balance", "a frame's balancing at scale"),
    "scene": ("bench:bench_scene", "loading a scene, built and cached"),
    "render": ("bench:bench_render", "draws per object count"),
    "frame": ("frame_bench:bench_frame", "one rank's per-frame CPU, phase by phase"),
    "growth": ("frame_bench:bench_growth", "balancing against objects, ranks and strips"),
    "floor": (None, "this machine's noise floor: identical work on every rank"),
    "present": ("present_bench:bench_present", "showing the wall: windows, swap skew"),
    "passes": ("passes_bench:bench_passes", "a second render pass against a joined one"),
    "imbalance": ("imbalance_bench:bench_imbalance", "what a rank's deviation is made of"),
    "exchange": ("exchange_bench:bench_exchange", "messages against the shared segment"),
    "network": ("network_bench:bench_network", "pixels between PCs on a simulated network: codecs, MB per frame"),
    "panel": ("panel_bench:bench_panel", "the operator's page: its cost to the frame, closed and open"),
    "stereo": ("stereo_bench:bench_stereo", "a stereo frame beside a mono frame of the same wall, per mode"),
    "projectors": ("projectors_bench:bench_projectors", "a projector wall's warp and blend pass beside monitors"),
    "onepass": ("onepass_bench:bench_onepass", "both eyes in one pass (instanced, geometry shader) against two"),
    "head": ("head_bench:bench_head", "a tracked head over UDP: motion to photon at latency 0, 1, 2"),
    "memory": ("memory_bench:bench_memory", "memory per rank and per host"),
    "moving": ("moving_bench:bench_moving", "moving scenes: per-frame balancing against static and none, their cost"),
    "series": ("series_bench:bench_series", "a simulation's time series against one still step: p99 frame, memory"),
    "memory-steps": ("memory_bench:bench_memory_steps", "memory step by step through setup"),
    "model-load": ("memory_bench:bench_model_load", "loading a model file: time and peak memory"),
    "textures": ("texture_bench:bench_textures", "a textured model against the same untextured: time, memory"),
    "longrun": ("longrun_bench:bench_longrun", "100,000 frames: frame time and memory over the run"),
    "recovery": ("recovery_bench:bench_recovery", "a rank killed: how long the wall is dark, step by step"),
    "gpu": ("gpu_bench:bench_gpu", "1, 4 and 16 ranks, hybrid at 4x4 (for a host with a GPU)"),
    "latency": (None, "frames in flight: wall time, input to photon"),
    "timeline": (None, "every rank's phases at --latency 0 and 1, plotted"),
    "peer": (None, "beside ParaView + IceT: --model FILE --ranks 1,4"),
    "simplify": (None, "the level-of-detail simplifiers compared: [--model FILE]"),
}


#: the flags of ``multigpu bench`` each benchmark reads (``bench NAME --help`` shows only those)
BENCH_FLAGS = {
    "floor": ("--quick", "--ranks", "--tile", "--display"),
    "peer": ("--quick", "--model", "--split", "--ranks", "--rounds", "--out"),
    "latency": ("--quick", "--rounds", "--out"),
    "simplify": ("--quick", "--model", "--out"),
    "timeline": ("--quick", "--out"),
}


def load(where: str):
    """The function at ``"module:function"`` of ``multigpu.studies``."""
    module, name = where.split(":")
    return getattr(importlib.import_module(f"multigpu.studies.{module}"), name)


def names_help(names) -> str:
    """``a | b | c``: the names as the help lists them."""
    return " | ".join(names)
