"""The Ray cluster recipe of docs/synthetic.md, against a real head started by address.

``ray start --head`` (Ray >= 2.59) turns token authentication on: a driver joins the cluster by
``--ray HOST:PORT`` only with ``RAY_AUTH_MODE=token`` and the cluster's token, and without them
the command exits 2 with one line saying so. The head runs in its own session (``--block``), is
bounded in time and is torn down by its process group, whatever the test does.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _sidql(args, env, timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sidql.commands.main", *args],
        env=env, cwd=REPO, capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


def test_synth_on_a_head_started_by_address_with_token_authentication():
    pytest.importorskip("ray")
    ray_exe = Path(sys.executable).parent / "ray"
    if not ray_exe.exists():
        pytest.skip(f"no ray command beside {sys.executable}")
    # short: Ray's Unix socket paths under --temp-dir must stay below ~100 characters
    tmp = Path(tempfile.mkdtemp(prefix="sidql-ray-", dir="/tmp"))
    try:
        _synth_on_a_cluster(ray_exe, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _synth_on_a_cluster(ray_exe: Path, tmp: Path) -> None:
    token = tmp / "token"
    token.write_text(os.urandom(32).hex())
    token.chmod(0o600)
    port = _free_port()
    base = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    base["HOME"] = str(tmp)  # no ~/.ray/auth_token of this machine's user is read
    base["PYTHONPATH"] = str(REPO)  # the cluster's workers import this checkout
    base["RAY_NUM_REDIS_GET_RETRIES"] = "3"  # a refused driver gives up in seconds, not 20
    cluster = {**base, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(token)}
    head = subprocess.Popen(
        [str(ray_exe), "start", "--head", "--block", f"--port={port}", "--num-cpus=2",
         "--node-ip-address=127.0.0.1", "--include-dashboard=false", "--disable-usage-stats",
         f"--temp-dir={tmp / 'ray'}"],
        env=cluster, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,  # its own process group: torn down as one below
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while True:  # the head's GCS accepts connections
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert head.poll() is None, "ray start --head exited"
                assert time.monotonic() < deadline, "the Ray head did not start in 60 s"
                time.sleep(0.3)
        address = f"127.0.0.1:{port}"
        args = ["synth", "--n", "2", "--kinds", "procedural", "--seconds", "0.5", "--quiet"]
        on_cluster = _sidql([*args, "--out", str(tmp / "cluster"), "--ray", address], cluster)
        assert on_cluster.returncode == 0, on_cluster.stderr[-2000:]
        refused = _sidql([*args, "--out", str(tmp / "refused"), "--ray", address], base)
        assert refused.returncode == 2
        last = refused.stderr.strip().splitlines()[-1]
        assert last.startswith("sidql synth: error: cannot join the Ray cluster") and (
            "RAY_AUTH_MODE=token" in last
        )
    finally:
        head.terminate()  # ray start --block stops the processes it started
        try:
            head.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait(timeout=10)
    local = _sidql([*args, "--out", str(tmp / "local"), "--workers", "1"], base)
    assert local.returncode == 0, local.stderr[-2000:]
    files = sorted(p.relative_to(tmp / "local") for p in (tmp / "local").rglob("*.npz"))
    assert len(files) == 2
    for f in files:  # the cluster's clips are the process's, bit for bit
        with np.load(tmp / "local" / f) as a, np.load(tmp / "cluster" / f) as b:
            assert a.files == b.files and all(np.array_equal(a[k], b[k]) for k in a.files)
