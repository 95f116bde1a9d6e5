"""Everything MuJoCo and motion data: Acclaim I/O, humanoid model, retargeting, velocities,
replay checks and rendering, physics (ground, contacts, IK, dynamics), forward simulation and the
batch executor. Never imports ``sidql``.

The flat API below is what a notebook needs; each name is loaded from its module on first use
(PEP 562), so ``import sim`` has no side effects and stays light, and ``import sim.motion.clip``
does not pull MuJoCo in. Rendering offscreen needs ``MUJOCO_GL`` (e.g. ``egl``) set before MuJoCo
is first imported; the ``sidql`` command line sets ``egl`` by default, library users set it
themselves.
"""

from importlib import import_module

_API = {
    "SidqlError": "sim.errors",
    "BadFileError": "sim.errors",
    "MotionDataError": "sim.errors",
    "ModelFileError": "sim.errors",
    "UnmetTargetError": "sim.errors",
    "UnknownNameError": "sim.errors",
    "UsageError": "sim.errors",
    "ArgumentTypeError": "sim.errors",
    "AllFailedError": "sim.errors",
    "MotionDataWarning": "sim.errors",
    "Clip": "sim.motion.clip",
    "load_npz": "sim.motion.clip",
    "save_npz": "sim.motion.clip",
    "write_atomic": "sim.files",
    "load_motion": "sim.motion.ingest",
    "load_clips": "sim.motion.ingest",
    "find_trials": "sim.motion.dataset",
    "ingest_directory": "sim.motion.dataset",
    "synthetic_motion": "sim.motion.synthetic",
    "humanoid_model": "sim.model.humanoid",
    "subject_model": "sim.motion.trial",
    "PointMotion": "sim.motion.points",
    "from_clip": "sim.replay.checks",
    "replay": "sim.replay.checks",
    "summarise": "sim.replay.checks",
    "render_frames": "sim.replay.video",
    "write_video": "sim.replay.video",
    "estimate_ground": "sim.physics.ground",
    "PhysicsJob": "sim.analysis.job",
    "synthesize": "sim.simulate.dataset",
    "run_batch": "sim.batch",
}

__all__ = sorted(_API)


def __getattr__(name: str):
    if name in _API:
        return getattr(import_module(_API[name]), name)
    raise AttributeError(f"module 'sim' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
