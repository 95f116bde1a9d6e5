"""MuJoCo's warnings go to standard error as one line each; no ``MUJOCO_LOG.TXT`` appears in the
working folder and nothing on standard output (``sim.mujoco_log``)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

DIVERGE = """
import mujoco, numpy as np
import sim.simulate.model  # what a simulating command imports
m = mujoco.MjModel.from_xml_string(
    "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>")
d = mujoco.MjData(m)
d.qvel[0] = np.nan
mujoco.mj_step(m, d)
print("counted", d.warning[mujoco.mjtWarning.mjWARN_BADQVEL].number)
"""


def _run(code: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": "disable"}
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120, check=True)  # fmt: skip


def test_a_diverging_step_warns_on_stderr_and_writes_no_log_file(tmp_path):
    done = _run(DIVERGE, tmp_path)
    assert list(tmp_path.iterdir()) == []  # no MUJOCO_LOG.TXT
    assert done.stdout == "counted 1\n"  # the count the simulation reads is kept
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("MuJoCo warning: Nan, Inf or huge value in QVEL")


def test_without_the_routing_mujoco_writes_its_log_file(tmp_path):
    """The oracle: the same step without ``sim`` writes the file into the working folder."""
    done = _run(DIVERGE.replace("import sim.simulate.model", "pass"), tmp_path)
    assert (tmp_path / "MUJOCO_LOG.TXT").exists() and "WARNING" in done.stderr


def test_a_handler_already_installed_stays(tmp_path):
    mine = "import mujoco\nseen = []\nmujoco.set_mju_user_warning(seen.append)\n"
    code = mine + DIVERGE + "print(len(seen))\n"
    done = _run(code, tmp_path)
    assert done.stdout.splitlines()[-1] == "1" and done.stderr == ""
    assert list(tmp_path.iterdir()) == []
