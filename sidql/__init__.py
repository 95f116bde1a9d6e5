"""The keyframe problem on top of ``sim``: the spherical chart, reconstructions, Q, selection
methods, the exact optimum, the learning environment and DQN, evaluation and the report, and the
motion codec.

The flat API below is what a notebook needs, e.g.::

    from sidql import load_clips, select, reconstruct, q_error, chart
    clip = load_clips("02.asf", "02_01.amc")[0]
    keys = select("optimal", clip, 10)
    rec = reconstruct(clip, keys, "hermite")  # or any name in RECONSTRUCTIONS
    q = q_error(chart(clip), keys)

Each name is loaded from its module on first use (PEP 562): ``import sidql`` has no side effects
and never imports torch (only ``sidql.learning.dqn`` / ``policy`` do, when training or deciding).
"""

from importlib import import_module

#: The version of the ``sidql`` distribution (pyproject.toml reads it from here).
__version__ = "0.1.0"

_API = {
    "load_clips": "sim.motion.ingest",
    "load_motion": "sim.motion.ingest",
    "Clip": "sim.motion.clip",
    "chart": "sidql.keyframes.spherical",
    "SphericalSeries": "sidql.keyframes.spherical",
    "POINTS": "sidql.keyframes.spherical",
    "select": "sidql.keyframes.methods",
    "available": "sidql.keyframes.methods",
    "register": "sidql.keyframes.methods",
    "reconstruction_of": "sidql.keyframes.methods",
    "reconstruct": "sidql.keyframes.reconstructions",
    "Reconstruction": "sidql.keyframes.reconstructions",
    "RECONSTRUCTIONS": "sidql.keyframes.reconstructions",
    "CURVES": "sidql.keyframes.curves",
    "q_error": "sidql.keyframes.metrics",
    "mpjpe_mm": "sidql.keyframes.metrics",
    "segment_cost_matrix": "sidql.keyframes.segment_costs",
    "optimal_table": "sidql.keyframes.optimal",
    "optimal_keyframes": "sidql.keyframes.optimal",
    "KeyframeEnv": "sidql.learning.env",
    "load_cases": "sidql.evaluation.cases",
    "evaluate": "sidql.evaluation.evaluate",
    "validate_clip": "sidql.evaluation.validation",
    "report_clips": "sidql.evaluation.report",
    "report_trial": "sidql.evaluation.report",
    "encode_clip": "sidql.codec.encode",
    "encode_files": "sidql.codec.encode",
    "decode_to_reconstruction": "sidql.codec.decode",
    "decode_file": "sidql.codec.decode",
}

__all__ = sorted(_API)


def __getattr__(name: str):
    if name in _API:
        return getattr(import_module(_API[name]), name)
    raise AttributeError(f"module 'sidql' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
