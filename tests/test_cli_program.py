"""``sidql`` as a program (:func:`sidql.commands.main.program`): a codec command run in a fresh
process writes, prints and exits exactly as :func:`~sidql.commands.main.main` run in this one,
its exit handlers run, and MuJoCo's GL context is never loaded."""

from __future__ import annotations

import os
import subprocess
import sys

from cli_run import REPO, cli, one_line_exit_2

from sidql.commands.main import main

#: a child that registers an exit handler, then runs ``sidql ARGV...`` as the installed command
#: does; the handler reports whether the GL stack was imported
PROBE = """
import atexit, sys
def report():
    print("exit handler ran; GL loaded:", "OpenGL" in sys.modules or "mujoco.egl" in sys.modules)
atexit.register(report)
class Torn:
    def __del__(self):
        print("torn down")
kept = Torn()  # freed only by the interpreter's teardown
from sidql.commands.main import program
sys.argv = ["sidql", *sys.argv[1:]]
program()
"""


def test_encode_as_a_program_writes_and_prints_what_main_does(cmu_dir, tmp_path, capsys):
    asf, amc = str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_01.amc")
    here, there = tmp_path / "here.sidq", tmp_path / "there.sidq"
    assert main(["encode", asf, amc, "--out", str(here), "--rate", "700"]) == 0
    printed = capsys.readouterr().out
    res = cli("encode", asf, amc, "--out", str(there), "--rate", "700")
    assert res.returncode == 0, res.stderr
    assert there.read_bytes() == here.read_bytes()
    assert res.stdout == printed.replace(str(here), str(there))  # every line, flushed


def test_a_codec_command_as_a_program_runs_exit_handlers_without_gl(cmu_dir, tmp_path):
    asf, amc = str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_01.amc")
    out = tmp_path / "w.sidq"
    res = subprocess.run(
        [sys.executable, "-c", PROBE, "encode", asf, amc, "--out", str(out), "--rate", "700"],
        capture_output=True, text=True, cwd=REPO, timeout=300,
        env={**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": "egl"},
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert res.stdout.rstrip().endswith("exit handler ran; GL loaded: False"), res.stdout
    assert "torn down" not in res.stdout and out.is_file()
    other = subprocess.run([sys.executable, "-c", PROBE, "--version"], capture_output=True,
                           text=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})  # fmt: skip
    assert other.returncode == 0 and "torn down" in other.stdout  # any other way out: as ever


def test_bad_input_to_a_codec_command_as_a_program_exits_2_with_one_line(tmp_path):
    missing = tmp_path / "none.sidq"
    one_line_exit_2(cli("decode", str(missing), "--out", str(tmp_path / "x.npz")), "none.sidq")
